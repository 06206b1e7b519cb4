"""Packaging checks: environment.yml mirrors pyproject.toml, ruff is clean, CLI runs."""

import ast
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]


def test_environment_yml_mirrors_pyproject_dependencies():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    pip_deps = {r.replace(" ", "") for r in pyproject["project"]["dependencies"]}
    environment = yaml.safe_load((ROOT / "environment.yml").read_text())
    conda_deps = {d.replace(" ", "") for d in environment["dependencies"] if isinstance(d, str)}
    assert conda_deps - {"pip", "python>=3.11"} == pip_deps
    assert {"pip": ["-e ."]} in environment["dependencies"]


def test_dependencies_have_lower_bounds_only():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    for requirement in pyproject["project"]["dependencies"]:
        assert ">=" in requirement
        assert "==" not in requirement
        assert "<" not in requirement.replace(">=", "")


@pytest.mark.skipif(shutil.which("ruff") is None, reason="ruff is not installed (extra 'test')")
def test_ruff_is_clean():
    result = subprocess.run(
        ["ruff", "check", "src", "tests", "benchmarks"], cwd=ROOT, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_console_script_reports_version():
    import mgelens

    result = subprocess.run(
        [sys.executable, "-m", "mgelens", "--version"], capture_output=True, text=True, check=True
    )
    assert mgelens.__version__ in result.stdout


def test_help_lists_every_command_with_its_own_help_without_importing_any():
    """`mgelens --help` reads each command's help from its source: the listing equals the
    help the command's `register` gives when imported, and no command module is loaded."""
    script = (
        "import sys\n"
        "from mgelens import cli\n"
        "parser = cli.build_parser()\n"
        "actions = [a for a in parser._actions if a.dest == 'command'][0]\n"
        "print({c.dest: c.help for c in actions._choices_actions})\n"
        "print(sorted(m for m in sys.modules if m.startswith('mgelens.commands.')))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    listed, imported = (ast.literal_eval(line) for line in result.stdout.splitlines())
    assert imported == []
    from mgelens import cli

    assert sorted(listed) == cli.command_names()
    for name in cli.command_names():
        registered = cli.build_parser(only=name)
        (command,) = [a for a in registered._actions if a.dest == "command"]
        assert listed[name] == command._choices_actions[0].help
        assert listed[name]
