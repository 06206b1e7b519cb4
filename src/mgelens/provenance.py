"""What code produced a result: the package version and a digest of its source.

The version number changes only when it is bumped; the digest changes with any edit to
the code of the package's Python files, and not with an edit to their docstrings,
comments or layout (:func:`code_form`): a corrected docstring does not make a sample's
fits stale. :func:`code_version` digests the whole package and is stored
in result files as provenance. :func:`command_version` digests only the files that one
``mgelens <command>`` runs (the command's module and every mgelens module it imports,
found statically): each workflow rule is keyed on its command's version (``params:
mgelens_version``) and each phase's checkpoint on the ``phase`` command's, so editing a
plotting module reruns the figures and not the fits, and a fit never resumes a
checkpoint written by other fitting code.
"""

import ast
import functools
import hashlib
from pathlib import Path

from mgelens import __version__

PACKAGE_ROOT = Path(__file__).resolve().parent


def source_digest(root: Path, files: list[Path] | None = None) -> str:
    """First 12 hex digits of the SHA-256 of ``files`` (default: every ``*.py`` file under
    ``root``): each file's path relative to ``root`` and its :func:`code_form`, in sorted
    path order."""
    digest = hashlib.sha256()
    for path in sorted(Path(root).rglob("*.py") if files is None else files):
        digest.update(Path(path).relative_to(root).as_posix().encode() + b"\0")
        digest.update(code_form(Path(path).read_bytes(), str(path)))
        digest.update(b"\0")
    return digest.hexdigest()[:12]


def code_form(source: bytes, filename: str = "<source>") -> bytes:
    """What of a Python file's ``source`` can change what it computes: its syntax tree
    without source positions and without the statements that are a bare string (module,
    class, function and attribute docstrings), so that comments, layout and docstrings
    drop out, written out by :func:`_tree_form`, which gives the same bytes on Python
    3.11 to 3.13. Only ``__doc__`` changes with docstrings, which the package reads for
    command-line help alone."""
    return _file_facts(source, filename)[1]


@functools.cache
def _file_facts(source: bytes, filename: str) -> tuple[tuple, bytes]:
    """The import statements of ``source`` as (level, module, names), ``import a.b`` as
    (0, "a.b", ()), and its
    :func:`code_form`, from one parse. Cached on the source's bytes: one snakemake start
    digests a dozen commands whose closures share most files, and parsing is what
    costs."""
    tree = ast.parse(source, filename=filename)
    imports = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imports.extend((0, alias.name, ()) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            imports.append((node.level, node.module, tuple(alias.name for alias in node.names)))
        for field in ("body", "orelse", "finalbody"):
            body = getattr(node, field, None)
            if isinstance(body, list) and body and isinstance(body[0], ast.stmt):
                kept = [statement for statement in body if not _is_bare_string(statement)]
                setattr(node, field, kept or [ast.Pass()])
    return tuple(imports), _tree_form(tree).encode()


def _tree_form(node) -> str:
    """A syntax tree as text: each node's class and its non-empty fields in name order.
    Unlike ``ast.dump``, whose output changes between Python versions (fields added
    empty, such as ``type_params`` in 3.12, and empty fields left out from 3.13), the
    same code gives the same text."""
    if isinstance(node, ast.AST):
        fields = "".join(
            f" {name}={_tree_form(value)}"
            for name in sorted(node._fields)
            if (value := getattr(node, name, None)) is not None and value != []
        )
        return f"({type(node).__name__}{fields})"
    if isinstance(node, list):
        return f"[{','.join(_tree_form(item) for item in node)}]"
    return repr(node)


def _is_bare_string(statement: ast.stmt) -> bool:
    return (
        isinstance(statement, ast.Expr)
        and isinstance(statement.value, ast.Constant)
        and isinstance(statement.value.value, str)
    )


def _module_file(root: Path, package: str, name: str) -> Path | None:
    """The file of module ``name`` (dotted, starting with ``package``) under ``root``,
    the package's folder: ``a/b.py`` or ``a/b/__init__.py``; ``None`` if neither exists."""
    parts = name.split(".")[1:]
    base = root.joinpath(*parts)
    for candidate in (base.with_suffix(".py") if parts else None, base / "__init__.py"):
        if candidate is not None and candidate.is_file():
            return candidate
    return None


def _imported_names(path: Path, module: str, package: str) -> set[str]:
    """Dotted names of the ``package`` modules that the file ``path`` (module ``module``)
    may import: every import statement in it, at any depth (imports inside functions
    count), with ``from x import y`` giving both ``x`` and ``x.y``, relative imports
    resolved, and every parent package of each name (importing ``a.b.c`` runs
    ``a/__init__.py`` and ``a/b/__init__.py``)."""
    is_package = path.name == "__init__.py"
    here = module if is_package else module.rpartition(".")[0]
    found = set()
    for name in _import_targets(path.read_bytes(), here, str(path)):
        if name == package or name.startswith(package + "."):
            parts = name.split(".")
            found.update(".".join(parts[: k + 1]) for k in range(len(parts)))
    return found


def _import_targets(source: bytes, here: str, filename: str) -> frozenset[str]:
    """Every name that the import statements of ``source`` (a module whose package is
    ``here``, read from ``filename``) name, relative imports resolved."""
    names = set()
    for level, module, imported in _file_facts(source, filename)[0]:
        if level:
            anchor = here.rsplit(".", level - 1)[0] if level > 1 else here
            base = f"{anchor}.{module}" if module else anchor
        else:
            base = module
        names.add(base)
        names.update(f"{base}.{name}" for name in imported)
    return frozenset(names)


def module_closure(module: str, root: Path | None = None, package: str = "mgelens") -> list[Path]:
    """The files that importing ``module`` can run: its own and those of every module of
    ``package`` (rooted at ``root``, default the installed package) it imports, directly or
    through others, sorted. Static and conservative: an import anywhere in a file counts."""
    root = PACKAGE_ROOT if root is None else Path(root)
    files: set[Path] = set()
    pending = [module]
    seen: set[str] = set()
    while pending:
        name = pending.pop()
        if name in seen:
            continue
        seen.add(name)
        path = _module_file(root, package, name)
        if path is None:  # a name imported from a module, not a module
            continue
        files.add(path)
        pending.extend(_imported_names(path, name, package) - seen)
    return sorted(files)


COMMAND_ENTRY = ("mgelens.cli", "mgelens.commands")
"""Modules that run before any command: the console script's parser and the commands'
package."""


def command_digest(command: str, root: Path | None = None) -> str:
    """:func:`source_digest` of the files that ``mgelens <command>`` runs: the command's
    module, :data:`COMMAND_ENTRY` and every mgelens module they import
    (:func:`module_closure`), in the package at ``root`` (default: the installed one).
    Raises ValueError for an unknown command."""
    root = PACKAGE_ROOT if root is None else Path(root)
    module = f"mgelens.commands.{command}"
    if _module_file(root, "mgelens", module) is None:
        raise ValueError(f"no command {command!r}: no module {module}")
    files = set()
    for name in (module, *COMMAND_ENTRY):
        files.update(module_closure(name, root))
    return source_digest(root, sorted(files))


@functools.cache
def command_version(command: str) -> str:
    """``<version>+<digest>`` of ``mgelens <command>`` (:func:`command_digest`; computed
    once per process), e.g. ``0.1.0+31c808a6ac53``."""
    return f"{__version__}+{command_digest(command)}"


@functools.cache
def code_digest() -> str:
    """:func:`source_digest` of the installed package (computed once per process)."""
    return source_digest(PACKAGE_ROOT)


def code_version() -> str:
    """``<version>+<digest>`` of the whole package, e.g. ``0.1.0+3f2a9c1b7e4d``."""
    return f"{__version__}+{code_digest()}"
