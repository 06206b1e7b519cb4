"""Shared test fixtures, and the background run of M1's SLaM chain."""

import os
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from workflow_run import (
    BACKGROUND_LENS,
    CHAIN_TIMEOUT,
    ROOT,
    snakemake_command,
    snakemake_environment,
)

SLACS_DIR = ROOT.parent / "shared" / "data" / "slacs"
"""The real SLACS cutouts: ``<repo root>/../shared/data/slacs``."""

POOLED_PHASES = "slam:\n  samplers:\n" + "".join(
    f"    {phase}: {{n_processes: 2}}\n" for phase in ("spix2", "light", "mass")
)
"""Config of the background chain: the quick profile with 2 processes in the phases that
run after the other tests (docs/slam.md, "Worker processes"): a likelihood pool in SPix2 and
LIGHT, MASS's two source meshes side by side (with the samples of one process). SP and
SPix1, which run while the other tests do, keep one process and draw the same samples
as in ``snakemake -j2``: there a pool only adds calls (SP: 1.16 times faster alone, 19 %
more calls; 354 s under the suite's load against 280 s in one process)."""


@pytest.fixture(scope="session")
def slacs_dir() -> Path:
    """Folder of the real SLACS lenses (one sub-folder per lens); skip if absent."""
    if not SLACS_DIR.is_dir():
        pytest.skip(
            f"shared SLACS data folder is absent: expected {SLACS_DIR} "
            "(the repository's sibling shared/data/slacs)"
        )
    return SLACS_DIR


class BackgroundChain:
    """``snakemake -c2 results/<lens>/recovery.json`` with :data:`POOLED_PHASES` in
    ``workdir``, started at once and running while the other tests do; :meth:`wait`
    returns the working directory."""

    def __init__(self, lens: str, workdir: Path):
        self.target = f"results/{lens}/recovery.json"
        self.workdir = workdir
        self.log = workdir / "snakemake.log"
        config = workdir / "pooled.yaml"
        config.write_text(POOLED_PHASES)
        arguments = (self.target, "-c2", "--configfile", str(ROOT / "config" / "config.yaml"))
        with self.log.open("w") as log:
            self.process = subprocess.Popen(
                snakemake_command(*arguments, str(config), workdir=workdir),
                cwd=ROOT, env=snakemake_environment(), stdout=log, stderr=subprocess.STDOUT,
                start_new_session=True,
            )  # fmt: skip

    def wait(self) -> Path:
        """Wait for the chain (at most :data:`CHAIN_TIMEOUT` s); fail with its log's tail."""
        try:
            code = self.process.wait(CHAIN_TIMEOUT)
        except subprocess.TimeoutExpired:
            self.stop()
            pytest.fail(f"{self.target} took more than {CHAIN_TIMEOUT} s (log: {self.log})")
        if code != 0:
            pytest.fail(f"{self.target} failed ({code}):\n{self.log.read_text()[-3000:]}")
        return self.workdir

    def stop(self) -> None:
        """Stop snakemake and the jobs it started, if still running."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGTERM)
            self.process.wait()


CHAIN_FIXTURES = {"background_chain", "chain_recovery"}
"""Fixtures through which a test reads the background chain (tests/test_workflow.py)."""


def _needs_background_chain(item: pytest.Item) -> bool:
    """Whether ``item`` reads M1's chain. Its own arguments are checked, not
    ``item.fixturenames``: that closure holds every autouse fixture, this one's too, so
    any selection of tests would start the 30-minute chain."""
    info = getattr(item, "_fixtureinfo", None)
    arguments = set(info.argnames) if info is not None else set()
    if not arguments & CHAIN_FIXTURES or item.get_closest_marker("skip"):
        return False
    callspec = getattr(item, "callspec", None)
    lens = callspec.params.get("chain_recovery", BACKGROUND_LENS) if callspec else BACKGROUND_LENS
    return lens == BACKGROUND_LENS


@pytest.fixture(scope="session", autouse=True)
def background_chain(request, tmp_path_factory) -> Iterator[BackgroundChain | None]:
    """M1's chain, started before the first test when a selected test reads it (else
    ``None``), so that its ~13 minutes overlap the rest of the suite; stopped at the end
    of the session if a test did not wait for it."""
    if not any(_needs_background_chain(item) for item in request.session.items):
        yield None
        return
    chain = BackgroundChain(BACKGROUND_LENS, tmp_path_factory.mktemp(f"{BACKGROUND_LENS}-chain"))
    yield chain
    chain.stop()


def pytest_addoption(parser):
    parser.addoption(
        "--recovery",
        action="store_true",
        help="also run the full SLaM chains on M2 and M3 (marker 'recovery', 14-22 min each)",
    )


def pytest_collection_modifyitems(config, items):
    """Skip the ``recovery`` tests unless ``--recovery`` is given (they exceed the suite's
    15-minute budget; README "Run it")."""
    if config.getoption("--recovery"):
        return
    skip = pytest.mark.skip(reason="full-chain recovery of M2, M3: run with --recovery -m recovery")
    for item in items:
        if item.get_closest_marker("recovery"):
            item.add_marker(skip)
