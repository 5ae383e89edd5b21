"""One version, one truth: the package, ``rehabbot --version``, ``CITATION.cff`` and the
CHANGELOG's newest entry name the same version. The docs take theirs from
the package (``docs/conf.py`` imports it), so a release edits ``rehabbot/common/version.py``,
``CITATION.cff`` and the CHANGELOG together or this fails."""

import re
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import yaml

import rehabbot

ROOT = Path(__file__).resolve().parents[1]


def changelog_versions() -> list[str]:
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    return re.findall(r"^## (\d+\.\d+\.\d+)\b", text, flags=re.MULTILINE)


def test_the_package_and_its_installed_metadata_agree():
    assert re.fullmatch(r"\d+\.\d+\.\d+", rehabbot.__version__)
    assert metadata.version("rehabbot") == rehabbot.__version__


def test_the_cli_prints_the_package_version():
    out = subprocess.run([sys.executable, "-m", "rehabbot", "--version"], check=True,
                         capture_output=True, text=True).stdout
    assert out.split() == ["rehabbot", rehabbot.__version__]


def test_citation_cff_names_the_package_version_and_cites_the_paper():
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert str(citation["version"]) == rehabbot.__version__
    titles = [ref["title"] for ref in citation.get("references", [])]
    assert any(title.startswith("RehabBot: Reinforcement learning environment") for title in titles)


def test_the_changelog_s_newest_entry_is_the_package_version():
    versions = changelog_versions()
    assert versions, "CHANGELOG.md has no '## X.Y.Z' entry"
    assert versions[0] == rehabbot.__version__, (
        f"CHANGELOG.md's newest entry is {versions[0]}, the package is {rehabbot.__version__}")
    assert len(set(versions)) == len(versions), f"an entry is repeated: {versions}"


def test_the_docs_take_their_version_from_the_package():
    text = (ROOT / "docs" / "conf.py").read_text(encoding="utf-8")
    assert "rehabbot.__version__" in text
    assert not re.search(r"^(release|version)\s*=\s*['\"]\d", text, flags=re.MULTILINE), (
        "docs/conf.py types a version instead of reading rehabbot.__version__")
