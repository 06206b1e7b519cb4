"""What code produced a result: the package version and a digest of its source.

The version number changes only when it is bumped; the digest changes with any edit to
the package's Python files. Workflow rules (``params: mgelens_version``) and sampler
checkpoints are keyed on :func:`code_version`, so a changed library reruns the fits and
never resumes a checkpoint written by other code.
"""

import functools
import hashlib
from pathlib import Path

from mgelens import __version__

PACKAGE_ROOT = Path(__file__).resolve().parent


def source_digest(root: Path) -> str:
    """First 12 hex digits of the SHA-256 of the ``*.py`` files under ``root`` (each file's
    path relative to ``root`` and its bytes, in sorted path order)."""
    digest = hashlib.sha256()
    for path in sorted(Path(root).rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


@functools.cache
def code_digest() -> str:
    """:func:`source_digest` of the installed package (computed once per process)."""
    return source_digest(PACKAGE_ROOT)


def code_version() -> str:
    """``<version>+<digest>``, e.g. ``0.1.0+3f2a9c1b7e4d``."""
    return f"{__version__}+{code_digest()}"
