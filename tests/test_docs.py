"""The documentation's commands run, and its relative links point somewhere.

- The tutorial (docs/tutorial/index.md): every ```bash block, in order, line by line, in
  one empty working folder, as a reader would type them.
- The README: its ```bash blocks of example commands the same way in a folder of its own
  (the set-up lines, which install the package or build the documentation, are skipped:
  ``SKIPPED_README``), then its ```python snippet in that folder.
- The writing commands both start with (the synthetic data, the paper's model, its
  prediction and comparison) run once per test run, shared by the xdist workers; each
  document's folder starts as a copy of their result, and runs the rest of its commands,
  with those that write nothing (``info``, ``rtd``, ``stationarity``) among the shared ones
  (``commands_left``).
- Relative links of README.md, CHANGELOG.md and the Markdown pages under docs/ point to an
  existing file, and to an existing heading where they name an anchor of a Markdown page
  (the slug rule of myst-parser and GitHub). The Sphinx build checks the pages' links
  too (warnings are errors); this test checks the README and the CHANGELOG, which the
  build does not read, and runs without Sphinx.

``cfbmarkov`` in a command is ``python -m cfbmarkov`` of this checkout (its src/ first on
PYTHONPATH), with ``NUMBA_NUM_THREADS=1``; after the first command of a list, a plain
``cfbmarkov`` command line calls the same ``cfbmarkov.cli.main`` in the test's process
(:func:`run_commands`).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from tests.shared_builds import built_once

ROOT = Path(__file__).resolve().parent.parent
TUTORIAL = ROOT / "docs" / "tutorial" / "index.md"
README = ROOT / "README.md"

#: README lines that set up the package, its tests or its documentation, not examples of
#: the tool: a line that starts with one of these is not run
SKIPPED_README = ("python -m pip", "python -m pytest", "python -m sphinx")

_FENCE = re.compile(r"^(```+|~~~+)\s*([\w+-]*)")


# -- Markdown ------------------------------------------------------------------------------


def fenced_blocks(text: str) -> list[tuple[str, str]]:
    """The fenced code blocks of a Markdown text, in order.

    Returns
    -------
    list of (str, str)
        (language, body) for each block; language is the fence's info word ("" if none).
    """
    blocks, lines = [], text.splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, lang, body = m.group(1), m.group(2), []
        i += 1
        while i < len(lines) and not lines[i].startswith(fence[0] * len(fence)):
            body.append(lines[i])
            i += 1
        blocks.append((lang, "\n".join(body)))
        i += 1
    return blocks


def shell_commands(block: str) -> list[str]:
    """The commands of a shell block: one a line, ``\\`` continuations joined, comments and
    blank lines dropped."""
    commands, pending = [], ""
    for line in block.splitlines():
        line = pending + (line.lstrip() if pending else line)
        if line.endswith("\\"):
            pending = line[:-1].rstrip() + " "
            continue
        pending = ""
        if line.strip() and not line.lstrip().startswith("#"):
            commands.append(line.strip())
    return commands


def doc_commands(path: Path, skip: tuple[str, ...] = ()) -> list[str]:
    """Every command of the ```bash blocks of ``path``, in order, less those starting with
    one of ``skip``."""
    commands = []
    for lang, body in fenced_blocks(path.read_text(encoding="utf-8")):
        if lang in ("bash", "sh", "shell", "console"):
            commands += [c for c in shell_commands(body) if not c.startswith(skip)]
    return commands


# -- running -------------------------------------------------------------------------------


def _environment(bin_dir: Path) -> dict[str, str]:
    """The process environment with ``cfbmarkov`` on PATH running this checkout."""
    bin_dir.mkdir(exist_ok=True)
    shim = bin_dir / "cfbmarkov"
    shim.write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} -m cfbmarkov "$@"\n')
    shim.chmod(shim.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT / "src")] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env["NUMBA_NUM_THREADS"] = "1"
    env["MPLBACKEND"] = "Agg"
    return env


#: characters that make a command line more than a program and its words
_SHELL_SYNTAX = set("|&;<>()$`\\\"'*?[]{}~#=")


def in_process_argv(command: str) -> list[str] | None:
    """The arguments of ``cfbmarkov.cli.main`` for a plain ``cfbmarkov`` command line (the
    program and its words, nothing else the shell would interpret); None for any other."""
    words = command.split()
    if len(words) < 2 or words[0] != "cfbmarkov" or _SHELL_SYNTAX & set(command):
        return None
    return words[1:]


def _run_in_process(argv: list[str], folder: Path) -> tuple[int, str]:
    """``cfbmarkov.cli.main(argv)`` in ``folder`` on one Numba thread (as the command line
    with ``NUMBA_NUM_THREADS=1``): its exit code and what it wrote on stderr."""
    import contextlib
    import io

    import numba

    from cfbmarkov.cli import main

    err, cwd, threads = io.StringIO(), os.getcwd(), numba.get_num_threads()
    os.chdir(folder)
    numba.set_num_threads(1)
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            code = main(argv)
    finally:
        numba.set_num_threads(threads)
        os.chdir(cwd)
    return code, err.getvalue()


def run_commands(commands: list[str], folder: Path, env: dict[str, str], source: str) -> None:
    """Run ``commands`` in order in ``folder``; fail on the first that exits non-zero.

    The first command runs as typed (``bash -c``, the ``cfbmarkov`` program of
    :func:`_environment`), and so does any that is not a plain ``cfbmarkov`` command line;
    the other ``cfbmarkov`` commands call ``cfbmarkov.cli.main`` in this process, which is
    what the program runs (``python -m cfbmarkov``), without a Python start and the imports
    for each."""
    for k, command in enumerate(commands):
        argv = in_process_argv(command) if k else None
        if argv is None:
            done = subprocess.run(["bash", "-c", command], cwd=folder, env=env,
                                  capture_output=True, text=True, timeout=600)
            code, stderr = done.returncode, done.stderr
        else:
            code, stderr = _run_in_process(argv, folder)
        if code != 0:
            pytest.fail(f"{source}: `{command}` exited with {code}\n"
                        f"stderr:\n{stderr[-4000:]}", pytrace=False)


#: verbs that write nothing: a document's command of one of them sees the same files when
#: it runs after the writing commands that follow it in the document
READ_ONLY_VERBS = ("info", "rtd", "stationarity")
#: options that change what a command prints, not what it writes
QUIET = ("-q", "--quiet")


def reads_only(command: str) -> bool:
    """Whether ``command`` is a ``cfbmarkov`` verb that writes no file."""
    words = shlex.split(command)
    return (len(words) > 1 and words[0] == "cfbmarkov" and words[1] in READ_ONLY_VERBS
            and not {"-o", "--output"} & set(words))


def _same_files(a: str, b: str) -> bool:
    """Whether two commands write the same files (the same words, ``-q`` aside)."""
    key = lambda c: [w for w in shlex.split(c) if w not in QUIET]  # noqa: E731
    return key(a) == key(b)


def common_start(a: list[str], b: list[str]) -> list[str]:
    """The writing commands that ``a`` and ``b`` both start with; commands that write
    nothing (:func:`reads_only`) are stepped over in either. Of two that differ by ``-q``
    alone, the one without it (its progress lines run too)."""
    wa, wb = [c for c in a if not reads_only(c)], [c for c in b if not reads_only(c)]
    n = 0
    while n < min(len(wa), len(wb)) and _same_files(wa[n], wb[n]):
        n += 1
    quiet = lambda c: bool(set(shlex.split(c)) & set(QUIET))  # noqa: E731
    return [y if quiet(x) and not quiet(y) else x for x, y in zip(wa[:n], wb[:n])]


def commands_left(commands: list[str], start: list[str]) -> list[str]:
    """The commands of a document left to run in a folder where ``start`` (its first
    writing commands, :func:`common_start`) has run: the read-only ones among those first
    commands, and every command after them, in order."""
    left, done = [], 0
    for command in commands:
        if done < len(start) and not reads_only(command):
            assert _same_files(command, start[done]), (command, start[done])
            done += 1
        else:
            left.append(command)
    assert done == len(start), "the document does not start with the shared commands"
    return left


@pytest.fixture(scope="session")
def shared_start(tmp_path_factory):
    """(commands, folder): the tutorial's and the README's common first writing commands
    (:func:`common_start`) and the folder they were run in, made once per test run (under
    xdist, by the first worker that asks; any other waits for it)."""
    start = common_start(doc_commands(TUTORIAL), doc_commands(README, SKIPPED_README))

    def build(seed: Path) -> None:
        (seed / "work").mkdir()
        run_commands(start, seed / "work", _environment(seed / "bin"),
                     "docs/tutorial/index.md and README.md")

    return start, built_once(tmp_path_factory, "docs-shared-start", build) / "work"


def _start_from(shared_start, commands: list[str], work: Path) -> list[str]:
    """Copy the shared folder to ``work``; the commands left to run."""
    start, seed = shared_start
    shutil.copytree(seed, work)
    return commands_left(commands, start)


def test_common_start():
    assert common_start(["a", "b", "c"], ["a", "b", "d"]) == ["a", "b"]
    assert common_start(["a"], ["b"]) == []
    assert common_start([], ["b"]) == []
    # commands that write nothing are stepped over; -q does not change what is written
    tutorial = ["cfbmarkov demo -o s", "cfbmarkov info s/r.h5", "cfbmarkov fit s/r.h5 -o m.h5",
                "cfbmarkov rtd m.h5", "cfbmarkov predict m.h5 -q -o p.h5",
                "cfbmarkov stationarity s/r.h5", "cfbmarkov fit s/r.h5 --states auto -o a.h5"]
    readme = ["cfbmarkov demo -o s", "cfbmarkov fit s/r.h5 -o m.h5",
              "cfbmarkov predict m.h5 -o p.h5", "cfbmarkov compare s/r.h5 p.h5 -o c"]
    start = common_start(tutorial, readme)
    assert start == ["cfbmarkov demo -o s", "cfbmarkov fit s/r.h5 -o m.h5",
                     "cfbmarkov predict m.h5 -o p.h5"]
    assert commands_left(tutorial, start) == [
        "cfbmarkov info s/r.h5", "cfbmarkov rtd m.h5", "cfbmarkov stationarity s/r.h5",
        "cfbmarkov fit s/r.h5 --states auto -o a.h5"]
    assert commands_left(readme, start) == ["cfbmarkov compare s/r.h5 p.h5 -o c"]
    assert not reads_only("cfbmarkov rtd m.h5 -o x") and reads_only("cfbmarkov info x.h5")


def test_only_plain_command_lines_run_in_process():
    assert in_process_argv("cfbmarkov fit a.h5 --lag 0.025 -o m.h5") == [
        "fit", "a.h5", "--lag", "0.025", "-o", "m.h5"]
    for command in ("cfbmarkov info a.h5 > out.txt", "cfbmarkov info a.h5 | head",
                    "cfbmarkov fit 'a b.h5'", "cfbmarkov info *.h5", "X=1 cfbmarkov info a.h5",
                    "python -m cfbmarkov info a.h5", "cfbmarkov", "cfbmarkov info $HOME/a.h5"):
        assert in_process_argv(command) is None, command


def test_shell_blocks_are_read_as_typed():
    text = ("intro\n```bash\ncfbmarkov a  # note\n# a comment\n\ncfbmarkov b \\\n  --x 1\n```\n"
            "```text\nnot run\n```\n```bash\npython -m pip install -e .\ncfbmarkov c\n```\n")
    blocks = fenced_blocks(text)
    assert [lang for lang, _ in blocks] == ["bash", "text", "bash"]
    assert shell_commands(blocks[0][1]) == ["cfbmarkov a  # note", "cfbmarkov b --x 1"]


def test_tutorial_has_its_commands():
    commands = doc_commands(TUTORIAL)
    # the chain the tutorial promises: make data, look, fit, RTD, predict, compare
    verbs = [c.split()[1] for c in commands if c.startswith("cfbmarkov ")]
    for verb in ("demo", "info", "fit", "rtd", "predict", "compare", "stationarity"):
        assert verb in verbs, f"the tutorial runs no `cfbmarkov {verb}`"
    assert all(c.startswith("cfbmarkov ") for c in commands), commands


@pytest.mark.slow
def test_tutorial_commands_run(tmp_path, shared_start):
    work = tmp_path / "work"
    commands = _start_from(shared_start, doc_commands(TUTORIAL), work)
    run_commands(commands, work, _environment(tmp_path / "bin"), "docs/tutorial/index.md")
    # what the tutorial then reads: the comparison's summary and the models
    for name in ("synth/reference.h5", "model.h5", "pred.h5", "compare/summary.json",
                 "auto.h5", "pred-auto.h5", "compare-auto/summary.json"):
        assert (work / name).is_file(), f"the tutorial's commands wrote no {name}"


def test_readme_example_commands_are_found():
    commands = doc_commands(README, SKIPPED_README)
    assert commands and all(c.startswith("cfbmarkov ") for c in commands), commands
    python = [body for lang, body in fenced_blocks(README.read_text(encoding="utf-8"))
              if lang == "python"]
    assert len(python) == 1


@pytest.mark.slow
def test_readme_examples_run(tmp_path, shared_start):
    work = tmp_path / "work"
    commands = _start_from(shared_start, doc_commands(README, SKIPPED_README), work)
    env = _environment(tmp_path / "bin")
    run_commands(commands, work, env, "README.md")
    for lang, body in fenced_blocks(README.read_text(encoding="utf-8")):
        if lang != "python":
            continue
        done = subprocess.run([sys.executable, "-c", body], cwd=work, env=env,
                              capture_output=True, text=True, timeout=600)
        if done.returncode != 0:
            pytest.fail(f"README.md: the python snippet exited with {done.returncode}\n"
                        f"stderr:\n{done.stderr[-4000:]}", pytrace=False)
        assert "E(RT) =" in done.stdout
    assert (work / "compare" / "summary.json").is_file()
    assert (work / "pred-py.h5").is_file()


# -- links ---------------------------------------------------------------------------------

_LINK = re.compile(r"\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")


def _heading_anchors_level() -> int:
    """``myst_heading_anchors`` of docs/conf.py: the deepest heading level with an anchor."""
    m = re.search(r"^myst_heading_anchors\s*=\s*(\d+)", (ROOT / "docs" / "conf.py").read_text(),
                  re.MULTILINE)
    return int(m.group(1)) if m else 0


def slugify(title: str) -> str:
    """A heading's anchor as myst-parser (``github`` preset) and GitHub make it: lower case,
    spaces to ``-``, every character but word characters, ``-`` and spaces dropped; the
    text of links and inline code kept."""
    title = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", title)
    return re.sub(r"[^\w\u4e00-\u9fff\- ]", "", title.lower().replace(" ", "-"))


def anchors(path: Path, max_level: int = 6) -> set[str]:
    """The heading anchors of a Markdown file, the n-th repeat of a slug suffixed ``-n``."""
    seen: set[str] = set()
    fence = None
    for line in path.read_text(encoding="utf-8").splitlines():
        m = _FENCE.match(line)
        if m:
            fence = None if fence and line.startswith(fence) else (fence or m.group(1))
            continue
        if fence:
            continue
        h = re.match(r"(#{1,6})\s+(.*?)\s*#*\s*$", line)
        if h and len(h.group(1)) <= max_level:
            base = slug = slugify(h.group(2))
            k = 1
            while slug in seen:
                slug, k = f"{base}-{k}", k + 1
            if slug:
                seen.add(slug)
    return seen


def relative_links(path: Path) -> list[tuple[int, str]]:
    """(line number, target) of each relative link of a Markdown file, outside code."""
    links, fence = [], None
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        m = _FENCE.match(line)
        if m:
            fence = None if fence and line.startswith(fence) else (fence or m.group(1))
            continue
        if fence:
            continue
        for target in _LINK.findall(_INLINE_CODE.sub("", line)):
            if not re.match(r"[a-zA-Z][a-zA-Z0-9+.-]*:", target):   # no scheme: relative
                links.append((number, target))
    return links


def broken_links(path: Path, docs_level: int, root: Path = ROOT) -> list[str]:
    """Each relative link (or image) of ``path`` under ``root`` whose file, or anchor in a
    Markdown file, is missing: one line each, naming the line and the target."""
    problems = []
    for number, target in relative_links(path):
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        where = f"{path.relative_to(root)}:{number}: {target}"
        if not dest.exists():
            problems.append(f"{where}: no such file")
        elif anchor and dest.suffix == ".md":
            # pages under docs/ get anchors down to myst_heading_anchors; GitHub, all
            in_docs = path.is_relative_to(root / "docs") and dest.is_relative_to(root / "docs")
            if anchor not in anchors(dest, docs_level if in_docs else 6):
                problems.append(f"{where}: no heading with anchor #{anchor}")
    return problems


def _pages() -> list[Path]:
    pages = [README, ROOT / "CHANGELOG.md"]
    for page in sorted((ROOT / "docs").rglob("*.md")):
        parts = page.relative_to(ROOT / "docs").parts
        # docs/results/paper-*/: reproductions' outputs, not pages (exclude_patterns)
        if parts[0] != "_build" and not (parts[0] == "results" and parts[1].startswith("paper-")):
            pages.append(page)
    return pages


def test_slugs_follow_myst():
    assert slugify("Outputs: atomic writes, locks, --force, exit codes") == \
        "outputs-atomic-writes-locks---force-exit-codes"
    assert slugify("Resampling (PEPT)") == "resampling-pept"
    assert slugify("3D data: projection and `depth` columns") == "3d-data-projection-and-depth-columns"
    assert slugify("See [the method](method.md)") == "see-the-method"


def test_link_check_finds_broken_links(tmp_path):
    (tmp_path / "a.md").write_text("# A\n## Part one\n## Part one\n```\n## Not a heading\n```\n")
    (tmp_path / "b.md").write_text(
        "[ok](a.md#part-one) [ok2](a.md#part-one-1) [code](a.md#not-a-heading)\n"
        "[gone](missing.md) [self](#b) ![img](a.md#nope) `[x](nothing.md)`\n"
        "# B\n[web](https://example.org/x.md)\n")
    problems = broken_links(tmp_path / "b.md", 4, root=tmp_path)
    assert problems == ["b.md:1: a.md#not-a-heading: no heading with anchor #not-a-heading",
                        "b.md:2: missing.md: no such file",
                        "b.md:2: a.md#nope: no heading with anchor #nope"]


@pytest.mark.parametrize("page", _pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    assert broken_links(page, _heading_anchors_level()) == []
