"""The code version that keys workflow reruns and checkpoints."""

import shutil

from mgelens import __version__
from mgelens.provenance import PACKAGE_ROOT, code_version, source_digest


def test_code_version_is_the_version_and_the_digest_of_the_installed_source():
    assert code_version() == f"{__version__}+{source_digest(PACKAGE_ROOT)}"


def test_source_digest_follows_python_files_only(tmp_path):
    package = tmp_path / "pkg"
    shutil.copytree(PACKAGE_ROOT / "search", package)
    before = source_digest(package)
    assert len(before) == 12
    assert source_digest(package) == before
    (package / "notes.txt").write_text("not code")
    assert source_digest(package) == before
    module = package / "priors.py"
    module.write_text(module.read_text() + "\n# an edit\n")
    edited = source_digest(package)
    assert edited != before
    module.rename(package / "renamed.py")
    assert source_digest(package) not in (before, edited)
