"""The library's layers (docs/architecture.md): every import of an mgelens module points
to the same layer or one below, and every module has a layer."""

import ast
import subprocess
import sys
from pathlib import Path

SOURCE = Path(__file__).resolve().parents[1] / "src" / "mgelens"

LAYERS = (
    ("foundation", ("mgelens", "_jit", "atomic", "threads", "memory", "values", "rejection",
                    "provenance", "sheet", "geometry", "grid")),
    ("data", ("imaging", "imaging_input", "mask", "convolve", "kernel_cumulants")),
    ("profiles", ("light", "mass", "analytic_blur", "image_multiplicity")),
    ("source", ("source",)),
    ("inversion", ("inversion",)),
    ("fit", ("fit", "fit_settings", "light_prior")),
    ("search", ("search",)),
    ("pipeline", ("pipeline",)),
    ("analysis", ("simulate", "mock_light", "mock_sources", "mock_lenses",
                  "independent_mock", "ellipse_fit", "isophotes", "source_share",
                  "isophote_recovery", "recovery", "coverage", "quality",
                  "overview", "summary",
                  "published", "mock_study", "smoothness", "chain_cost")),
    ("plot", ("plot",)),
    ("commands", ("commands", "cli", "__main__")),
)  # fmt: skip
"""Bottom to top; a name is a module or a package (all its modules), relative to mgelens."""


def module_name(path: Path) -> str:
    parts = path.relative_to(SOURCE).with_suffix("").parts
    return ".".join(("mgelens", *parts)).removesuffix(".__init__")


MODULES = {module_name(path): path for path in SOURCE.rglob("*.py")}


def layer_of(module: str) -> int:
    """Index in :data:`LAYERS` of an mgelens module (KeyError if it has none)."""
    relative = module.removeprefix("mgelens").removeprefix(".") or "mgelens"
    for index, (_, names) in enumerate(LAYERS):
        if any(relative == name or relative.startswith(f"{name}.") for name in names):
            return index
    raise KeyError(module)


def imported_modules(path: Path) -> set[str]:
    """The mgelens modules a file imports, at module level or inside functions (for
    ``from mgelens.x import y`` the module mgelens.x.y if it exists, else mgelens.x)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names if alias.name.startswith("mgelens")}
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("mgelens"):
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                found.add(full if full in MODULES else node.module)
    return found


def test_every_module_has_a_layer():
    unplaced = []
    for module in MODULES:
        try:
            layer_of(module)
        except KeyError:
            unplaced.append(module)
    assert not unplaced, f"add these modules to a layer of docs/architecture.md: {unplaced}"


def test_imports_point_down():
    upward = [
        f"{module} ({LAYERS[layer_of(module)][0]}) -> {target} ({LAYERS[layer_of(target)][0]})"
        for module, path in sorted(MODULES.items())
        for target in sorted(imported_modules(path))
        if target in MODULES and layer_of(target) > layer_of(module)
    ]
    assert not upward, "imports pointing up a layer:\n" + "\n".join(upward)


def test_the_check_sees_an_upward_import(tmp_path):
    """The parser finds an import hidden in a function, and the layers rank it upward."""
    path = tmp_path / "probe.py"
    path.write_text("def f():\n    from mgelens.search import sampler\n    return sampler\n")
    assert imported_modules(path) == {"mgelens.search.sampler"}
    assert layer_of("mgelens.search.sampler") > layer_of("mgelens.fit")


def test_configuration_loads_no_numerics():
    """The workflow validates settings on every DAG parse: pipeline.settings must stay free
    of numba, scipy, dynesty and numpy (a fresh interpreter, so nothing is preloaded)."""
    heavy = ("numba", "scipy", "dynesty", "numpy", "nautilus", "astropy")
    code = (
        f"import sys, mgelens.pipeline.settings; print([m for m in {heavy!r} if m in sys.modules])"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.strip()
    assert loaded == "[]"
