import sys

from cfbmarkov.cli import main

sys.exit(main())
