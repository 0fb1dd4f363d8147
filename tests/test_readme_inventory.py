"""The README's module inventory matches the tree: every package of `sea_hil` (its folders from pyproject.toml's
`package-dir`) and of `bench` has a bullet, every module of a package is named in its bullet (`name.py`), and every
bullet and module named exists."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROOTS = ("bench",)   # beside the folders of pyproject.toml's package-dir (not installed)


def inventory(readme: str) -> dict[str, set[str]]:
    """Folder (`protocol/`, `sea_hil/config/`, ...) -> the `*.py` names its bullet lists."""
    section = readme.split("### Module inventory", 1)[1].split("\n#", 1)[0]
    out: dict[str, set[str]] = {}
    folder = None
    for line in section.splitlines():
        bullet = re.match(r"- `([\w/]+/)`", line)
        if bullet:
            folder = bullet.group(1)
            assert folder not in out, f"two bullets for {folder}"
            out[folder] = set()
        elif not line.startswith("  "):
            folder = None
        if folder is not None:
            out[folder] |= set(re.findall(r"`(\w+)\.py`", line))
    return out


def tree(repo: Path = REPO) -> dict[str, set[str]]:
    """Folder -> its modules, for every package folder (one with an `__init__.py`) under the roots."""
    with (repo / "pyproject.toml").open("rb") as handle:
        roots = list(tomllib.load(handle)["tool"]["setuptools"]["package-dir"].values()) + list(ROOTS)
    out: dict[str, set[str]] = {}
    for root in roots:
        for init in sorted((repo / root).rglob("__init__.py")):
            folder = init.parent.relative_to(repo).as_posix() + "/"
            out.setdefault(folder, {p.stem for p in init.parent.glob("*.py") if p.stem != "__init__"})
    return out


def test_every_package_and_module_is_listed_and_every_listed_one_exists() -> None:
    listed, actual = inventory((REPO / "README.md").read_text(encoding="utf-8")), tree()
    assert sorted(set(actual) - set(listed)) == [], "packages missing from the README's inventory"
    assert sorted(set(listed) - set(actual)) == [], "README lists packages that do not exist"
    for folder, modules in actual.items():
        assert sorted(modules - listed[folder]) == [], f"{folder}: modules missing from the README's inventory"
        assert sorted(listed[folder] - modules) == [], f"{folder}: README lists modules that do not exist"


def test_the_check_sees_a_missing_and_a_stale_entry(tmp_path: Path) -> None:
    (tmp_path / "pkg" / "sub").mkdir(parents=True)
    for rel in ("pkg/__init__.py", "pkg/a.py", "pkg/sub/__init__.py", "pkg/sub/b.py", "bench/__init__.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    (tmp_path / "pyproject.toml").write_text('[tool.setuptools.package-dir]\n"pkg" = "pkg"\n')
    readme = "### Module inventory\n- `pkg/` — `a.py`,\n  `gone.py`\n- `bench/` — none\n\n## Next\n- `x/` `c.py`\n"
    assert inventory(readme) == {"pkg/": {"a", "gone"}, "bench/": set()}
    assert tree(tmp_path) == {"pkg/": {"a"}, "pkg/sub/": {"b"}, "bench/": set()}
