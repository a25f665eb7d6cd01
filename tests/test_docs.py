"""The documents: pictures and relative links point at files that exist; quoted messages are
today's; the README's commands and options exist and its DuckDB one-liner works; every file
path and module the docs cite exists; the nav's titles and the pages' titles are unique; the site
builds with --strict (broken links and anchors fail) and its generated reference pages hold the
KPI catalogue and every file kind's schema."""

from __future__ import annotations

import ast
import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from .conftest import ROOT

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(doc: Path) -> None:
    targets = [t.split("#", 1)[0] for t in LINK.findall(doc.read_text(encoding="utf-8"))
               if not re.match(r"[a-z]+:|#", t)]
    missing = [t for t in targets if not (doc.parent / t).exists()]
    assert missing == []


def test_the_studies_page_shows_its_three_plots() -> None:
    text = (ROOT / "docs" / "studies" / "2026-11-agv-model-dynamics.md").read_text(encoding="utf-8")
    shown = re.findall(r"!\[[^\]]*\]\(\.\./(img/[^)]+\.png)\)", text)
    assert len(shown) == 3


def test_every_picture_is_shown_by_a_page() -> None:
    """Every picture in docs/img is shown by some page (from any folder of docs/)."""
    shown = {m for doc in sorted((ROOT / "docs").rglob("*.md"))
             for m in re.findall(r"!\[[^\]]*\]\((?:\.\./)*(img/[^)]+\.png)\)",
                                 doc.read_text(encoding="utf-8"))}
    assert shown == {f"img/{p.name}" for p in (ROOT / "docs" / "img").glob("*.png")}


def test_the_readme_quotes_todays_error_messages(tmp_path: Path) -> None:
    """The README's two example errors are what the command prints today, word for word."""
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    (tmp_path / "s.yaml").write_text(
        "name: s\nlayout: " + str(ROOT / "layouts" / "tiny_loop.yaml")
        + "\nfleet: {size: 1, colour: red}\n", encoding="utf-8")
    for args in (["run", "s.yaml"],
                 ["run", str(ROOT / "experiments" / "tiny_loop.yaml"), "--hours", "nan"]):
        result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", *args], cwd=tmp_path,
                                capture_output=True, text=True, timeout=120)
        assert result.returncode == 2
        message = result.stderr.strip().splitlines()[-1]
        assert message.startswith("fleet-sim: error: ")
        assert f"`{message}`" in readme


def test_the_readme_duckdb_one_liner_queries_a_sweep(tmp_path: Path) -> None:
    """The README's query of sweep.duckdb runs as shown, from the folder `make run` is run in,
    on a (one-run) sweep written where the README says."""
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.sweep import sweep

    from .conftest import write_yaml

    (line,) = [line for line in (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
               if line.startswith('.venv/bin/python -c "import duckdb')]
    experiment = load_experiment(write_yaml(tmp_path / "e.yaml", {
        "name": "warehouse_sizing", "scenario": str(ROOT / "experiments" / "tiny_loop.yaml"),
        "overrides": {"duration_h": 0.5, "warmup_h": 0.1}, "factors": {"fleet.size": [1]},
        "replications": 1}))
    sweep(experiment, tmp_path / "results" / "warehouse_sizing", workers=1, quiet=True)
    command = [sys.executable, *shlex.split(line)[1:]]
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "throughput_per_hour" in result.stdout and "fleet.size=1__r00" in result.stdout


def _readme_commands() -> list[list[str]]:
    """Every `fleet-sim` command line of the README's code blocks, as arguments."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    lines = [line for block in re.findall(r"```sh\n(.*?)```", text, re.DOTALL)
             for line in block.splitlines()]
    commands = []
    for line in lines:
        words = shlex.split(line.split("#", 1)[0])
        if words and words[0] in ("fleet-sim", ".venv/bin/fleet-sim"):
            commands.append(words[1:])
    return commands


def test_the_readme_commands_and_their_options_exist(capsys: pytest.CaptureFixture[str]) -> None:
    """Each command the README shows is a command today and takes the options it is shown
    with (its --help names them), and each `make` target it names is in the Makefile."""
    from fleet_sim.cli import main

    commands = _readme_commands()
    assert len({c[0] for c in commands}) >= 10  # the README shows the handful of commands
    for args in commands:
        if args[0] == "layout" and args[1:2] not in (["check"], ["import"], ["export"]):
            args = ["layout", "check", *args[1:]]  # `layout FILE` is `layout check FILE`
        two_words = args[:2] in (["layout", "check"], ["layout", "import"],
                                 ["layout", "export"], ["profile", "import"])
        name = args[:2] if two_words else args[:1]
        with pytest.raises(SystemExit) as stop:
            main([*name, "--help"])
        assert stop.value.code == 0, args
        shown = capsys.readouterr().out
        options = [a.split("=", 1)[0] for a in args if a.startswith("--")]
        assert [o for o in options if o not in shown] == [], args
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    targets = set(re.findall(r"`make ([a-z]+)`|^make ([a-z]+)",
                             (ROOT / "README.md").read_text(encoding="utf-8"), re.MULTILINE))
    named = {t for pair in targets for t in pair if t}
    assert {"run", "test", "docs"} <= named
    assert [t for t in named if not re.search(rf"^{t}:", makefile, re.MULTILINE)] == []


def _hook() -> ModuleType:
    spec = importlib.util.spec_from_file_location("docs_hook", ROOT / "tools" / "docs_hook.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_file_kind_has_its_generated_reference_page() -> None:
    hook = _hook()
    assert hook.missing_format_pages(ROOT / "docs") == []
    with pytest.raises(ValueError, match="unknown generated part"):
        hook.expand("<!-- fleet-sim: schema nope -->")


def test_the_commands_page_shows_every_registered_command_and_option() -> None:
    """docs/reference/commands.md is generated from the command registry: every command
    (compare included) has its heading and usage line, every option its row."""
    from fleet_sim.cli import REGISTRY, Command, OneOf

    page = (ROOT / "docs" / "reference" / "commands.md").read_text(encoding="utf-8")
    assert "<!-- fleet-sim: commands -->" in page
    text = _hook().expand(page)
    assert "compare" in REGISTRY and "layout import" in REGISTRY
    missing = []
    for name, entry in REGISTRY.items():
        if f"### {name} {{#{name.replace(' ', '-')}}}" not in text:
            missing.append(name)
        if isinstance(entry, Command):
            if f"usage: fleet-sim {name} " not in text:
                missing.append(f"{name} usage")
            args = [a for item in entry.arguments
                    for a in (item.args if isinstance(item, OneOf) else (item,))]
            section = text.split(f"usage: fleet-sim {name} ", 1)[-1].split("\n### ", 1)[0]
            missing += [f"{name} {flag}" for a in args for flag in a.flags
                        if flag.startswith("--") and f"| `{flag}" not in section]
    assert missing == []

def test_the_site_builds_strict_with_the_generated_reference(tmp_path: Path) -> None:
    """`mkdocs build --strict` (as `make docs`) succeeds; the KPI page lists every KPI of the
    catalogue and each format page every key of its file kind's schema, every model's."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("material")
    from fleet_sim.analysis.kpis import BY_TYPE, CATALOGUE
    from fleet_sim.config.schemas import FILE_MODELS, json_schema

    site = tmp_path / "site"
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert result.returncode == 0, result.stderr[-3000:]
    kpi_page = (site / "reference" / "kpi-catalogue" / "index.html").read_text(encoding="utf-8")
    assert "fleet-sim: kpi-catalogue" not in kpi_page
    assert [k.name for k in CATALOGUE if f"<code>{k.name}</code>" not in kpi_page] == []
    assert [k.name for k in BY_TYPE
            if f"<code>by_type.&lt;type&gt;.{k.name}</code>" not in kpi_page] == []
    for kind in FILE_MODELS:
        page = (site / "reference" / "formats" / kind / "index.html").read_text(encoding="utf-8")
        schema = json_schema(kind)
        models = [schema, *schema.get("$defs", {}).values()]
        keys = {key for model in models for key in model.get("properties", {})}
        assert keys and [k for k in sorted(keys) if f"<code>{k}</code>" not in page] == [], kind
    from fleet_sim.cli import REGISTRY

    commands = (site / "reference" / "commands" / "index.html").read_text(encoding="utf-8")
    assert "fleet-sim: commands" not in commands
    assert [n for n in REGISTRY if f'id="{n.replace(" ", "-")}"' not in commands] == []
    index = json.loads((site / "search" / "search_index.json").read_text(encoding="utf-8"))
    assert any(doc["location"].startswith("studies/") for doc in index["docs"])


SOURCE_FILES = ("rss-agv-001-core-logic.ja.md", "carriro-ad-plus-serial-api-v1.4.ja.md",
                "ktm-02-commands.ja.md", "tabo-commands.ja.tsv", "agv-3-protocol.sv.md")
"""The source documents' file names, outside this repository: a reader cannot open them."""
FILE_CITATION = re.compile("|".join(
    [*(re.escape(name) for name in SOURCE_FILES), r"\bspecs/", r"\.\./shared/",
     r"\bDESIGN\.md\b", r"\bDESIGN reading\b"]))
CITING = ("fleet_sim", "agv_model", "userfiles", "bench", "tools", "docs", "experiments",
          "layouts", "tests", ".ci", "README.md", "Makefile", "mkdocs.yml", "pyproject.toml")


def _project_files() -> list[Path]:
    files = []
    for top in (ROOT / name for name in CITING):
        for path in [top] if top.is_file() else sorted(top.rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".png" \
                    and path != Path(__file__):
                files.append(path)
    return files


def test_the_source_documents_are_cited_by_title_never_by_file() -> None:
    """The source documents and the design file are not in the repository: code, profiles, docs
    and tests cite them by title and section (RSS-AGV-001, 4.2.9; the CarriRo AD+ External
    Serial Interface API Reference, version 1.4, Appendix E; docs/background/spec-readings.md
    for fleet_sim's readings), never by file name, specs/ path or DESIGN.md."""
    files = _project_files()
    assert len(files) > 100 and ROOT / "agv_model" / "profiles" / "tabo.yaml" in files
    found = [f"{path.relative_to(ROOT)}:{number}: {match.group()}"
             for path in files
             for number, line in enumerate(
                 path.read_bytes().decode("utf-8", errors="replace").splitlines(), 1)
             for match in FILE_CITATION.finditer(line)]
    assert found == []


PACKAGES = ("fleet_sim", "agv_model", "userfiles")
CITED_PATH = re.compile(r"(?<![\w./-])((?:fleet_sim|agv_model|userfiles|tests|bench|tools|docs|"
                        r"experiments|layouts)/[\w./-]*[\w/])(::\w+)?(?![<*{])")
CITED_MODULE = re.compile(r"(?<![\w./-])((?:fleet_sim|agv_model|userfiles)(?:\.[A-Za-z_]\w*)+)")
PLACEHOLDER = re.compile(r"/[A-Z]{2,}\b")
"""`layouts/NAME.yaml`, `docs/studies/YYYY-MM-<what>.md`: a name the reader chooses."""


def _citing_texts() -> list[tuple[Path, str]]:
    """The texts that cite files and modules: the README, the docs, pyproject.toml, the
    Makefile, mkdocs.yml, the comments of the bundled experiments and layouts, and the module
    docstrings of the code, the tools, the benches and the tests."""
    files = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), ROOT / "pyproject.toml",
             ROOT / "Makefile", ROOT / "mkdocs.yml",
             *sorted((ROOT / "experiments").glob("*.yaml")),
             *sorted((ROOT / "layouts").glob("*.yaml"))]
    texts = [(path, path.read_text(encoding="utf-8")) for path in files]
    for top in (*PACKAGES, "bench", "tools", "tests"):
        for path in sorted((ROOT / top).rglob("*.py")):
            docstring = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")))
            if docstring:
                texts.append((path, docstring))
    return texts


def _top_level_names(body: list[Any]) -> dict[str, Any]:
    """The names a module (or class) body defines or imports, guarded ones included."""
    names: dict[str, Any] = {}
    for node in body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names[node.name] = node
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update((n.id, node) for t in targets for n in ast.walk(t)
                         if isinstance(n, ast.Name))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update(((a.asname or a.name).split(".")[0], node) for a in node.names)
        elif isinstance(node, (ast.If, ast.Try)):
            blocks = [node.body, node.orelse, *(h.body for h in getattr(node, "handlers", []))]
            for block in blocks:
                names.update(_top_level_names(block))
    return names


def _module_exists(dotted: str) -> bool:
    """A dotted name exists if it is a module or package, or a name such a module defines (a
    class's member too; a package's lazily loaded name is one its __init__ spells out)."""
    parts = dotted.split(".")
    for length in range(len(parts), 0, -1):
        base = ROOT.joinpath(*parts[:length])
        source = base / "__init__.py" if base.is_dir() else base.with_suffix(".py")
        if not source.is_file():
            continue
        rest = parts[length:]
        if not rest:
            return True
        text = source.read_text(encoding="utf-8")
        names = _top_level_names(ast.parse(text).body)
        if rest[0] not in names:
            return f'"{rest[0]}"' in text
        node = names[rest[0]]
        if len(rest) > 1 and isinstance(node, ast.ClassDef):
            return rest[1] in _top_level_names(node.body) or any(
                isinstance(n, ast.Attribute) and n.attr == rest[1] for n in ast.walk(node))
        return True
    return False


def _path_exists(path: str, test: str | None) -> bool:
    target = ROOT / path.rstrip(".")
    if test is None:
        return target.exists()
    return target.is_file() and f"def {test[2:]}(" in target.read_text(encoding="utf-8")


def test_every_path_and_module_the_docs_cite_exists() -> None:
    """Every file path (`fleet_sim/sim/engine.py`, `tests/test_docs.py::test_...`,
    `docs/how-to/install.md`) and dotted module name (`fleet_sim.sim.traffic.control.Traffic`)
    that the README, the docs, the build files, the bundled files' comments and the module
    docstrings cite exists: a module that moves takes its citations with it. A path written by
    a command (after `--out`) and a placeholder (`layouts/NAME.yaml`) are not citations."""
    texts = _citing_texts()
    assert len(texts) > 200
    stale = []
    for path, text in texts:
        for match in CITED_PATH.finditer(text):
            cited, test = match.groups()
            written = text[:match.start()].endswith("--out ")
            if not written and not PLACEHOLDER.search(cited) and not _path_exists(cited, test):
                stale.append(f"{path.relative_to(ROOT)}: {cited}{test or ''}")
        stale += [f"{path.relative_to(ROOT)}: {match.group(1)}"
                  for match in CITED_MODULE.finditer(text)
                  if not match.group(1).endswith((".py", ".md", ".yaml"))
                  and not _module_exists(match.group(1))]
    assert stale == []


def _nav_titles(items: list[Any]) -> list[str]:
    """Every title of mkdocs.yml's nav, sections' and pages' alike (an untitled entry has none)."""
    titles = []
    for item in items:
        if isinstance(item, dict):
            for title, value in item.items():
                titles.append(title)
                if isinstance(value, list):
                    titles += _nav_titles(value)
    return titles


def _page_title(page: Path) -> str:
    """A page's H1: its first `# ` line outside a fenced block."""
    fenced = False
    for line in page.read_text(encoding="utf-8").splitlines():
        fenced ^= line.startswith("```")
        if not fenced and line.startswith("# "):
            return line[2:].strip()
    return ""


def test_the_nav_titles_and_the_page_titles_are_unique() -> None:
    """No two entries of the site's nav and no two pages share a title (`Layout files: how to
    write one` and `Layout file format (generated reference)`), so a reader knows which page a
    title names; every page has a title."""
    import yaml

    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))["nav"]
    titles = [t.casefold() for t in _nav_titles(nav)]
    assert len(titles) > 50
    assert sorted({t for t in titles if titles.count(t) > 1}) == []
    pages = {page: _page_title(page) for page in sorted((ROOT / "docs").rglob("*.md"))}
    assert [str(p.relative_to(ROOT)) for p, title in pages.items() if not title] == []
    h1s = [title.casefold() for title in pages.values()]
    assert sorted({t for t in h1s if h1s.count(t) > 1}) == []
