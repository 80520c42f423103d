"""Every code block of README.md and docs/*.md runs here (the conventions are written in
docs/README.md, "Code blocks in these pages"):

* ``python``: executed in order, in one fresh namespace per page;
* ``bash``: every line is a ``mitld-lp`` command, run through ``mitld_lp.cli.main``; it
  must exit 0, or the status a trailing ``# exit N`` names;
* ``toml`` / ``prism`` / ``python`` with ``file=NAME``: written to NAME for the blocks
  after it (not run);
  ``toml`` without a name: a complete model file, loaded with ``loads_model``;
* ``text``: output shown to the reader, not code;
* a fence right after ``<!-- not run: REASON -->`` is skipped (the install commands).

Each page runs in its own empty folder holding a link to ``models/``, so the pages can
name the bundled models and write files without touching the repository.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
import sys
import types
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
NOT_RUN = re.compile(r"<!--\s*not run:\s*(\S.*?)\s*-->")
FENCE = re.compile(r"^```(\S*)(.*)$")
RUNNABLE = {"python", "bash", "toml", "prism"}
SHOWN = {"text"}
# The pages may skip very few blocks; each needs a reason in its marker.
MAX_NOT_RUN = 2


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    lang: str
    options: dict[str, str]
    code: str
    skipped: str | None  # the reason, when marked not run


def blocks(page: Path) -> list[Block]:
    lines = page.read_text(encoding="utf-8").split("\n")
    out: list[Block] = []
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        lang = m.group(1)
        options = dict(opt.split("=", 1) for opt in m.group(2).split() if "=" in opt)
        start = i
        i += 1
        body: list[str] = []
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        if i == len(lines):
            raise AssertionError(f"{page.name}:{start + 1}: code block is not closed")
        prev = next((ln for ln in reversed(lines[:start]) if ln.strip()), "")
        marker = NOT_RUN.search(prev)
        out.append(Block(page, start + 1, lang, options, "\n".join(body) + "\n",
                         marker.group(1) if marker else None))
        i += 1
    return out


def test_every_block_has_a_known_kind() -> None:
    skipped = []
    for page in PAGES:
        for b in blocks(page):
            where = f"{page.name}:{b.line}"
            assert b.lang in RUNNABLE | SHOWN, (
                f"{where}: block of kind {b.lang!r}; use one of {sorted(RUNNABLE | SHOWN)}")
            if b.skipped is not None:
                skipped.append(where)
    assert len(skipped) <= MAX_NOT_RUN, f"too many blocks marked not run: {skipped}"


def test_docs_exist_and_stay_inside_the_repository() -> None:
    names = {p.name for p in PAGES}
    assert {"README.md", "formulas.md", "semantics.md", "model-files.md", "worlds.md",
            "results.md"} <= names
    tracked = {p.name for pattern in ("*.md", "docs/*.md", "experiments/**/*.md")
               for p in ROOT.glob(pattern)}
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        # every Markdown file a page names exists in this repository (a user has no other)
        for named in re.findall(r"[\w./-]*?([\w-]+\.md)\b", text):
            assert named in tracked, f"{page.name}: names {named}, which is not in the repository"
        assert not re.search(r"\.\./\w", text), f"{page.name}: a path leaves the repository"
        # relative links point at files that exist
        for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text):
            assert (page.parent / target).exists(), f"{page.name}: broken link {target}"


def test_the_readme_lists_every_bundled_file_with_what_it_needs() -> None:
    """The README's table of bundled models names every file under ``models/`` and no
    other; a row says the ``[prism]`` extra where the file is or reads a PRISM program,
    and names every other file of ``models/`` the file reads."""
    models = ROOT / "models"
    section = (ROOT / "README.md").read_text(encoding="utf-8").split("\n## Model files")[1]
    section = section.split("\n## ")[0]
    rows = {m.group(1): [c.strip() for c in m.group(2).split(" | ")]
            for m in re.finditer(r"^\| `([^`]+)` \| (.+) \|$", section, re.M)}
    files = {p.relative_to(models).as_posix(): p for p in models.rglob("*")
             if p.is_file() and not any(part.startswith(".") for part in p.parts)}
    assert set(rows) == set(files)
    for name, path in files.items():
        scenario, needs = rows[name]
        text = path.read_text(encoding="utf-8") if path.suffix == ".toml" else ""
        prism = path.suffix == ".prism" or re.search(r"^\[prism\]", text, re.M) is not None
        assert ("`[prism]` extra" in needs) is prism, name
        for other in files:  # a file it reads, relative to its own folder
            if other != name and f'"{other}"' in text:
                assert f"`{other}`" in needs, (name, other)
        assert scenario, name


def _run_bash(block: Block) -> None:
    from mitld_lp.cli import main

    for k, raw in enumerate(block.code.splitlines()):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{block.page.name}:{block.line + 1 + k}"
        expect = 0
        m = re.search(r"#\s*exit\s+(\d+)\s*$", line)
        if m:
            expect = int(m.group(1))
            line = line[: m.start()].strip()
        words = shlex.split(line)
        assert words[0] == "mitld-lp", f"{where}: a bash block runs only mitld-lp commands"
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = main(words[1:])
        assert status == expect, f"{where}: `{line}` exited {status}: {err.getvalue()}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_page_runs(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from mitld_lp.model import loads_model

    (tmp_path / "models").symlink_to(ROOT / "models", target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    # a real module, so that dataclasses and pickling inside a page can find it
    module = types.ModuleType(f"docs_{page.stem}")
    monkeypatch.setitem(sys.modules, module.__name__, module)
    namespace = module.__dict__
    ran = 0
    for b in blocks(page):
        if b.skipped is not None or b.lang in SHOWN:
            continue
        where = f"{page.name}:{b.line}"
        if "file" in b.options:
            (tmp_path / b.options["file"]).write_text(b.code, encoding="utf-8")
        elif b.lang == "python":
            code = compile(b.code, where, "exec")
            with contextlib.redirect_stdout(io.StringIO()):
                exec(code, namespace)  # noqa: S102 - running the documentation is the test
        elif b.lang == "bash":
            _run_bash(b)
        elif b.lang == "toml":
            loads_model(b.code, source=where)
        else:
            raise AssertionError(f"{where}: a {b.lang} block needs file=NAME")
        ran += 1
    assert ran > 0 or page.name == "README.md" and not blocks(page)
