"""What a non-editable install needs (CI installs the wheel): every package directory is listed
in pyproject.toml, and the tests import the package, never scripts from tools/."""
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_directory_is_in_pyproject():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "clpost").rglob("__init__.py")
             if "__pycache__" not in p.parts}
    assert found, "no package found"
    missing = sorted(found - listed)
    assert not missing, f"add {missing} to [tool.setuptools] packages in pyproject.toml (CI installs the wheel)"


def test_tests_import_the_package_not_tools():
    bad = []
    for path in sorted((ROOT / "tests").glob("*.py")):
        if path.name == Path(__file__).name:
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"sys\.path\.(insert|append)|spec_from_file_location|[\"']tools[\"']\)?\s*\)", line):
                bad.append(f"{path.name}:{n}: {line.strip()}")
    assert not bad, "move what tests need from tools/ into the package:\n" + "\n".join(bad)
