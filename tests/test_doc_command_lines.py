"""Every ``cfbmarkov ...`` command line shown in README.md and docs/how-to/*.md parses (it is
not run): options, their values (negative ones included, ``--region -0.045:0.045,...``)
and the verbs are as the parser has them."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from cfbmarkov.cli import build_parser, main
from cfbmarkov.cli.options import join_dash_values

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs" / "how-to").glob("*.md"))]
BLOCK = re.compile(r"^```(?:bash|sh|shell|console|text)\s*$(.*?)^```", re.M | re.S)


def _command_lines(path: Path) -> list[str]:
    """The ``cfbmarkov`` lines of the code blocks of ``path``, continuations joined."""
    lines = []
    for block in BLOCK.findall(path.read_text(encoding="utf-8")):
        text = re.sub(r"\\\n\s*", " ", block)
        for line in text.splitlines():
            line = line.strip().removeprefix("$ ")
            # a command, not a line of its output ("cfbmarkov import: read ...")
            if line.startswith("cfbmarkov ") and not line.split()[1].endswith(":"):
                lines.append(line.split(" #")[0])
    return lines


CASES = [(path.relative_to(ROOT).as_posix(), line) for path in DOCS
         for line in _command_lines(path)]


def test_the_docs_show_command_lines():
    assert len(CASES) >= 20
    assert any("--region -0.045" in line for _, line in CASES)


@pytest.mark.parametrize("where, line", CASES)
def test_documented_command_line_parses(where, line):
    parser = build_parser()
    words = re.sub(r"\[(-[^\]]*)\]", r"\1", line)      # optional parts shown in [ ] included
    argv = [w for w in shlex.split(words)[1:] if w not in ("|", ">")]
    try:
        args = parser.parse_args(join_dash_values(parser, argv))
    except SystemExit as exc:
        pytest.fail(f"{where}: {line!r} does not parse (exit {exc.code})")
    assert args.command == argv[0]


@pytest.mark.parametrize("value", ["-0.045:0.045,0:0.95", "-.045:.045,0:0.95",
                                   "-4.5e-2:4.5e-2,0:0.95"])
def test_region_values_starting_with_a_minus(value):
    parser = build_parser()
    for argv in (["import", "d", "--format", "lammps", "-o", "r.h5", "--region", value],
                 ["import", "--region", value, "d", "--format", "lammps", "-o", "r.h5"]):
        args = parser.parse_args(join_dash_values(parser, argv))
        assert args.region[0][0] == pytest.approx(-0.045) and args.source == ["d"]


def test_a_missing_value_is_still_an_error(capsys):
    assert main(["import", "d", "--format", "lammps", "-o", "r.h5", "--region"]) == 2
    assert "expected one argument" in capsys.readouterr().err
    # a value that is an option stays an option
    assert main(["import", "d", "--format", "lammps", "--region", "-o", "r.h5"]) == 2


def _outputs(line: str) -> list[str]:
    """The output paths a command line names (``-o``/``--output``)."""
    words = shlex.split(line)
    return [words[i + 1] for i, w in enumerate(words[:-1]) if w in ("-o", "--output")]


@pytest.mark.parametrize("doc", ["README.md", "docs/tutorial/index.md"])
def test_example_outputs_are_ignored_by_git(doc):
    """Run from the repository's root, the examples' outputs (a folder or a file each) leave
    no untracked file for git to show: .gitignore lists each (or its ``*.h5``)."""
    import shutil
    import subprocess

    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    outputs = {o.rstrip("/") for line in _command_lines(ROOT / doc) for o in _outputs(line)
               if not o.startswith("/")}
    outputs.add("cfbmarkov-demo")                 # `cfbmarkov demo`'s default folders
    outputs.add("cfbmarkov-demo-synthetic")
    assert "synth" in outputs
    probes = [f"{o}/x.png" if not o.endswith(".h5") else o for o in sorted(outputs)]
    done = subprocess.run(["git", "check-ignore", "--no-index", *probes], cwd=ROOT,
                          capture_output=True, text=True)
    ignored = {line.strip() for line in done.stdout.splitlines()}
    assert not set(probes) - ignored, f"not in .gitignore: {sorted(set(probes) - ignored)}"
