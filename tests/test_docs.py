"""The documentation works as written: the site builds in strict mode, and every code block
of README.md and of the pages under docs/ runs, or says why it cannot.

Blocks by their language: ``python`` is executed and ``bash`` (``sh``, ``console``,
``shell``) is run, each in a fresh process in a temporary folder that holds copies of the
repository's ``campaigns/``, ``examples/``, ``scenarios/``, ``benchmarks/`` and
``tests/data/`` (so relative paths work, and outputs land in the temporary folder);
``toml`` is parsed, and loaded where it has the shape of a scenario (whole, or a fragment
loaded over paper_case) or of a campaign spec; ``xml`` is parsed; ``text`` is an output
sample or a diagram and is not run; ``{code-cell}`` cells are executed by the site's build;
other ``{directive}`` fences are not code. A block that cannot run here (an install, a Ray
cluster, a display, a long campaign) is preceded by ``<!-- not run: REASON -->``.
"""

from __future__ import annotations

import copy
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [
    ROOT / "README.md",
    *sorted(
        p
        for p in DOCS.rglob("*.md")
        if not {"_build", "jupyter_execute"} & set(p.relative_to(DOCS).parts)
    ),
]
#: what a bash or python block finds beside it: copies of these, relative to the root
FOLDERS = ("campaigns", "examples", "scenarios", "benchmarks", "tests/data")
RUN = {"python", "bash", "sh", "console", "shell"}
NOT_CODE = {"text"}
SKIP = re.compile(r"<!--\s*not run:(?P<reason>.*?)-->\s*$", re.S)
FENCE = re.compile(
    r"^(?P<fence>```+)(?P<info>[^\n`]*)\n(?P<body>.*?)^(?P=fence)[ \t]*$", re.M | re.S
)
SCENARIO_TABLES = {
    "name",
    "description",
    "duration",
    "seed",
    "physics",
    "team",
    "gains",
    "noise",
    "mission",
    "obstacles",
    "faults",
    "network",
    "onboard",
    "fdir",
    "supervisor",
}


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # of the opening fence, 1-based
    info: str
    body: str
    skip: str | None  # the reason given in a <!-- not run: ... --> just before it

    @property
    def language(self) -> str:
        return self.info.split()[0] if self.info.split() else ""

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks_of(page: Path) -> list[Block]:
    """The fenced blocks of a page, each with the reason of a not-run comment before it."""
    text = page.read_text(encoding="utf-8")
    found = []
    for m in FENCE.finditer(text):
        before = text[: m.start()].rstrip()
        comment = before[before.rfind("<!--") :] if before.endswith("-->") else ""
        skip = SKIP.fullmatch(comment)
        found.append(
            Block(
                page,
                text.count("\n", 0, m.start()) + 1,
                m.group("info").strip(),
                m.group("body"),
                skip.group("reason").strip() if skip else None,
            )
        )
    return found


BLOCKS = [b for page in PAGES for b in blocks_of(page)]


def _ids(b: Block) -> str:
    return f"{b.where}-{b.language or 'none'}"


def test_the_pages_and_their_blocks_are_found():
    """README.md and the docs' pages are read, and the blocks are where the pages put them."""
    assert ROOT / "README.md" in PAGES and DOCS / "index.md" in PAGES
    languages = {b.language for b in BLOCKS}
    assert {"python", "bash", "toml", "text", "{code-cell}"} <= languages, languages


def test_every_not_run_comment_gives_a_reason_and_stands_before_a_block():
    """A ``<!-- not run: ... -->`` says why, and marks the block right after it (a marker
    left alone, or one without a reason, is a mistake)."""
    problems = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"<!--\s*not run:(.*?)-->", text, flags=re.S):
            line = text.count("\n", 0, m.start()) + 1
            if len(m.group(1).split()) < 2:
                problems.append(f"{page.relative_to(ROOT)}:{line}: no reason given")
            if not re.match(r"\s*```", text[m.end() :]):
                problems.append(f"{page.relative_to(ROOT)}:{line}: no code block follows")
    assert not problems, "\n".join(problems)


def test_every_block_says_what_it_is():
    """Each block has a language this test knows, or a reason why it is not run."""
    known = RUN | NOT_CODE | {"toml", "xml"}
    unknown = [
        b.where
        for b in BLOCKS
        if b.skip is None and b.language not in known and not b.language.startswith("{")
    ]
    assert not unknown, f"blocks with no language this test runs (mark them): {unknown}"


@pytest.fixture
def workdir(tmp_path: Path) -> Path:
    """An empty folder holding copies of the folders the pages' commands name."""
    for name in FOLDERS:
        shutil.copytree(ROOT / name, tmp_path / name, ignore=shutil.ignore_patterns("renders"))
    return tmp_path


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.setdefault("MUJOCO_GL", "egl")
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p
    )  # the package of this checkout, installed or not
    return env


RUNNABLE = [b for b in BLOCKS if b.skip is None and b.language in RUN]


@pytest.mark.parametrize("block", RUNNABLE, ids=_ids)
def test_each_python_and_bash_block_runs(block: Block, workdir: Path):
    """The block runs to the end with exit status 0, as a reader would paste it."""
    if block.language == "python":
        command = [sys.executable, "-c", block.body]
    else:
        command = ["bash", "-e", "-o", "pipefail", "-c", block.body]
    done = subprocess.run(
        command,
        cwd=workdir,
        env=_environment(),
        capture_output=True,
        text=True,
        timeout=900,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 0, (
        f"{block.where} exited {done.returncode}\n{block.body}\n"
        f"--- stdout\n{done.stdout[-4000:]}\n--- stderr\n{done.stderr[-4000:]}"
    )


def _merge(into: dict, extra: dict) -> None:
    for key, value in extra.items():
        if isinstance(value, dict) and isinstance(into.get(key), dict):
            _merge(into[key], value)
        else:
            into[key] = copy.deepcopy(value)


TOML = [b for b in BLOCKS if b.skip is None and b.language == "toml"]


@pytest.mark.parametrize("block", TOML, ids=_ids)
def test_each_toml_block_parses_and_loads(block: Block, tmp_path: Path, monkeypatch):
    """Every TOML block parses; a scenario loads (a fragment over paper_case), a campaign
    spec loads as a spec; a robot file, whose MJCF is not here, is parsed only."""
    from dftc_mujoco import scenario
    from dftc_mujoco.campaign import spec

    monkeypatch.syspath_prepend(str(ROOT / "examples"))  # mylab's blocks, as from examples/
    data = tomllib.loads(block.body)
    if "mjcf" in data:
        assert {"base", "drive"} <= set(data) or "holonomic" in data, block.where
    elif "scenario" in data and "runs" in data:
        path = tmp_path / "spec.toml"
        path.write_text(block.body, encoding="utf-8")
        assert spec.load(path).runs == data["runs"]
    elif set(data) <= SCENARIO_TABLES:
        if not {"team", "mission", "gains"} <= set(data):  # a fragment: over paper_case
            whole = tomllib.loads((ROOT / "scenarios" / "paper_case.toml").read_text("utf-8"))
            _merge(whole, data)
            data = whole
        scenario.from_dict(data, source=block.where)


XML = [b for b in BLOCKS if b.skip is None and b.language == "xml"]


@pytest.mark.parametrize("block", XML, ids=_ids)
def test_each_xml_block_parses(block: Block):
    ET.fromstring(block.body)


def test_no_development_history_in_the_readme_or_the_docs():
    """The pages speak of the project as it is: no work sessions, issue numbers, commit
    hashes or dated narration (that is CHANGELOG.md's)."""
    patterns = {
        "a work session": r"\bsessions?\b",
        "an issue number": r"\bissue \d+",
        "a date": r"\b20\d\d-\d\d-\d\d\b",
        "a commit hash": r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b",
    }
    found = []
    for page in PAGES:
        for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            for what, pattern in patterns.items():
                if re.search(pattern, line):
                    found.append(f"{page.relative_to(ROOT)}:{n}: {what}: {line.strip()[:100]}")
    assert not found, "\n".join(found)


def test_the_site_builds_in_strict_mode(tmp_path: Path):
    """``sphinx-build -W --keep-going -n``: a broken link or reference, a docstring that is
    not valid reStructuredText or a tutorial cell that raises fails the build; the
    tutorials really run the simulator."""
    missing = [m for m in ("sphinx", "furo", "myst_parser", "myst_nb") if not _has(m)]
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (pip install -e '.[docs]')")
    out = tmp_path / "html"
    strict = ["-W", "--keep-going", "-n", "-q"]
    done = subprocess.run(
        [sys.executable, "-m", "sphinx", *strict, "-b", "html", str(DOCS), str(out)],
        cwd=ROOT,
        env=_environment(),
        capture_output=True,
        text=True,
        timeout=900,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-6000:]
    for page in ("index", "api", "guide/first-run", "tutorials/paper-case", "notes"):
        assert (out / f"{page}.html").is_file(), page
    tutorial = (out / "tutorials" / "paper-case.html").read_text(encoding="utf-8")
    assert "excluded from the team" in tutorial  # the executed run's own events
    assert not (DOCS / "jupyter_execute").exists()


def _has(module: str) -> bool:
    return importlib.util.find_spec(module) is not None
