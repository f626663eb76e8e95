import sys

try:
    from cfbmarkov.cli import program
except KeyboardInterrupt:      # Ctrl-C while the modules load: one line, exit 130
    print("cfbmarkov: interrupted", file=sys.stderr)
    sys.exit(130)

program()
