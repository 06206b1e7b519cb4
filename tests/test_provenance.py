"""The code version that keys workflow reruns and checkpoints."""

import re
import shutil
from pathlib import Path

import pytest

from mgelens import __version__
from mgelens.provenance import (
    PACKAGE_ROOT,
    code_form,
    code_version,
    command_digest,
    command_version,
    module_closure,
    source_digest,
)


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
    module.write_text(module.read_text() + "\nEDITED = 1\n")
    edited = source_digest(package)
    assert edited != before
    module.rename(package / "renamed.py")
    assert source_digest(package) not in (before, edited)


def test_docstrings_comments_and_layout_leave_the_digest_and_code_changes_it(tmp_path):
    """A corrected docstring, a comment or a reflowed line does not make results stale;
    a changed constant, operator or string that is not a docstring does."""
    package = tmp_path / "pkg"
    package.mkdir()
    module = package / "model.py"
    original = (
        '"""Module docstring."""\n\n'
        "SCALE = 2.0\n"
        '"""Attribute docstring."""\n\n\n'
        "def f(x):\n"
        '    """Function docstring."""\n'
        "    return SCALE * x  # a comment\n\n\n"
        "class Model:\n"
        '    """Only a docstring."""\n\n\n'
        "def g():\n"
        '    raise ValueError("a message")\n'
    )

    def digest(text):
        module.write_text(text)
        return source_digest(package)

    before = digest(original)
    for same in (
        original.replace("Module docstring.", "Module docstring, corrected."),
        original.replace("Attribute docstring.", "Other words."),
        original.replace("Function docstring.", "The contract, in full."),
        original.replace('    """Only a docstring."""\n', '    """Two."""\n    """Three."""\n'),
        original.replace("  # a comment", "  # another comment"),
        original.replace("return SCALE * x", "return (\n        SCALE\n        * x\n    )"),
        "# a header comment\n\n" + original,
    ):
        assert digest(same) == before, same
    for different in (
        original.replace("SCALE = 2.0", "SCALE = 3.0"),
        original.replace("SCALE * x", "SCALE + x"),
        original.replace("a message", "another message"),
        original.replace('    """Only a docstring."""\n', "    pass\n    pass\n"),
    ):
        assert digest(different) != before, different


def test_the_code_form_is_the_same_text_on_every_python_version():
    """Written out field by field with empty fields left out, the form does not follow
    ``ast.dump``'s changes between versions (``type_params`` added in 3.12, empty fields
    dropped in 3.13): this text is what 3.11, 3.12 and 3.13 give."""
    source = b'"""Doc."""\ndef f(x):\n    """Doc."""\n    return x + 1  # note\n'
    assert code_form(source) == (
        b"(Module body=[(FunctionDef args=(arguments args=[(arg arg='x')]) "
        b"body=[(Return value=(BinOp left=(Name ctx=(Load) id='x') op=(Add) "
        b"right=(Constant value=1)))] name='f')])"
    )


def test_a_command_is_keyed_on_the_modules_it_imports_and_no_others():
    phase = {
        p.relative_to(PACKAGE_ROOT).as_posix() for p in module_closure("mgelens.commands.phase")
    }
    for fitting in ("fit.py", "pipeline/run.py", "pipeline/phases/mass.py", "search/sampler.py",
                    "inversion/solve.py"):  # fmt: skip
        assert fitting in phase
    assert not any(name.startswith("plot/") for name in phase)
    summary = {
        p.relative_to(PACKAGE_ROOT).as_posix() for p in module_closure("mgelens.commands.summary")
    }
    assert "plot/summary.py" in summary
    assert command_version("phase") == f"{__version__}+{command_digest('phase')}"
    with pytest.raises(ValueError, match="no command 'fly'"):
        command_digest("fly")


def test_editing_a_plotting_module_changes_the_figures_version_and_not_the_fits(tmp_path):
    root = tmp_path / "mgelens"
    shutil.copytree(PACKAGE_ROOT, root, ignore=shutil.ignore_patterns("__pycache__"))
    before = {command: command_digest(command, root) for command in ("phase", "summary")}

    def edit(relative):
        path = root / relative
        path.write_text(path.read_text() + "\nEDITED = 1\n")
        return {command: command_digest(command, root) for command in ("phase", "summary")}

    after_plot = edit("plot/summary.py")
    assert after_plot["phase"] == before["phase"]
    assert after_plot["summary"] != before["summary"]
    after_fit = edit("fit.py")
    assert after_fit["phase"] != after_plot["phase"]


def test_module_closure_follows_relative_and_function_level_imports(tmp_path):
    root = tmp_path / "mgelens"
    (root / "sub").mkdir(parents=True)
    files = {
        "__init__.py": "",
        "sub/__init__.py": "from . import helper\n",
        "sub/helper.py": "X = 1\n",
        "sub/entry.py": "def run():\n    from ..lazy import thing\n    return thing\n",
        "lazy.py": "from mgelens.sub.helper import X as thing\n",
        "unused.py": "",
    }
    for relative, text in files.items():
        (root / relative).write_text(text)
    closure = module_closure("mgelens.sub.entry", root)
    assert [p.relative_to(root).as_posix() for p in closure] == [
        "__init__.py",
        "lazy.py",
        "sub/__init__.py",
        "sub/entry.py",
        "sub/helper.py",
    ]


def test_an_import_added_to_a_file_is_followed_in_the_same_process(tmp_path):
    """The parsed imports are cached on each file's content, not its path: editing a file
    between two closures in one process (as a test or a long session may) is seen."""
    root = tmp_path / "mgelens"
    root.mkdir()
    for name in ("__init__.py", "entry.py", "late.py"):
        (root / name).write_text("")
    before = module_closure("mgelens.entry", root)
    (root / "entry.py").write_text("from mgelens import late\n")
    after = module_closure("mgelens.entry", root)
    assert [p.name for p in before] == ["entry.py"]
    assert [p.name for p in after] == ["__init__.py", "entry.py", "late.py"]


def test_every_workflow_rule_is_keyed_on_the_command_it_runs():
    rules = Path(__file__).resolve().parents[1] / "workflow" / "rules"
    keyed = 0
    for smk in rules.glob("*.smk"):
        text = smk.read_text()
        assert "code_version" not in text, smk
        for block in re.split(r"\n(?=rule |use rule )", text):
            versions = re.findall(r'mgelens_version=command_version\("(\w+)"\)', block)
            commands = re.findall(r'"mgelens (\w+) ', block)
            if versions:
                keyed += 1
                assert versions == commands[:1], (smk.name, block[:60])
    assert keyed >= 10
