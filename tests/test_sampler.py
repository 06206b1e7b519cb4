"""Nested sampling: evidence and posterior of a known Gaussian, rejections, resume, backends."""

import dataclasses
import json
import math
import platform
import resource
import uuid
from pathlib import Path

import dynesty.bounding
import h5py
import numba
import numpy as np
import pytest

from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.search.model import ParameterSpace
from mgelens.search.posterior import SamplerOutput, pool_runs
from mgelens.search.priors import Uniform
from mgelens.search.sampler import (
    NAUTILUS_NETWORK_MAX_ITER,
    CheckpointMismatchError,
    nautilus_live_points,
    resolve_sample_method,
    run_nested,
)
from mgelens.search.sampler_settings import SamplerSettings
from mgelens.threads import blas_threads

MEAN = np.array([0.5, -0.3])
SIGMA = np.array([0.2, 0.4])
BOX = 5.0
LOG_Z = -math.log((2 * BOX) ** 2)
"""ln Z of a unit-normalised Gaussian likelihood under a uniform prior on [−5, 5]²: the
Gaussian's mass inside the box is 1 − O(1e−30), so Z = 1/area."""

SPACE = ParameterSpace.from_priors({"toy.x": Uniform(-BOX, BOX), "toy.y": Uniform(-BOX, BOX)})
FAST = SamplerSettings(n_live=100, progress_every=1e9)
ACCURATE = SamplerSettings(n_live=300, progress_every=1e9)


class Interrupted(Exception):
    """Stands for a wall-time kill in the middle of a run."""


class GaussianLikelihood:
    """Normalised 2-D Gaussian.

    Optionally rejects x < ``reject_below`` (and leaves a marker file per rejection in
    ``marker_folder``), or raises :class:`Interrupted` once it has been called more than
    ``stop_after`` times and the file ``stop_once_exists`` exists.
    """

    def __init__(
        self, reject_below=-math.inf, marker_folder=None, stop_after=None, stop_once_exists=None
    ):
        self.reject_below, self.marker_folder = reject_below, marker_folder
        self.stop_after, self.stop_once_exists = stop_after, stop_once_exists
        self.calls = self.rejected = 0

    def __call__(self, x: np.ndarray) -> float:
        self.calls += 1
        if (
            self.stop_after is not None
            and self.calls > self.stop_after
            and self.stop_once_exists.exists()
        ):
            raise Interrupted
        if x[0] < self.reject_below:
            self.rejected += 1
            if self.marker_folder is not None:  # one file per rejection, from any process
                (Path(self.marker_folder) / uuid.uuid4().hex).touch()
            return REJECTED_LOG_LIKELIHOOD
        z = (x - MEAN) / SIGMA
        return float(-0.5 * z @ z - np.log(2 * np.pi * SIGMA.prod()))


def failing_likelihood(x: np.ndarray) -> float:
    raise AssertionError("a finished checkpoint must not call the likelihood")


def posterior_moments(output):
    weights = output.weights
    mean = weights @ output.samples
    std = np.sqrt(weights @ (output.samples - mean) ** 2)
    return mean, std


def assert_recovers_gaussian(output, tolerance=math.inf):
    """ln Z within 3 reported errors (and ``tolerance``); posterior mean and width."""
    error = output.log_evidence_error
    assert abs(output.log_evidence - LOG_Z) < min(3 * error, tolerance)
    mean, std = posterior_moments(output)
    np.testing.assert_allclose(mean, MEAN, atol=0.1)
    np.testing.assert_allclose(std, SIGMA, rtol=0.15)


@pytest.fixture(scope="module")
def static_run():
    likelihood = GaussianLikelihood()
    lines: list[str] = []
    output = run_nested(likelihood, SPACE, ACCURATE, seed=11, log=lines.append)
    return likelihood, output, lines


def test_static_recovers_evidence_and_posterior(static_run):
    likelihood, output, _ = static_run
    assert_recovers_gaussian(output, tolerance=0.3)
    assert output.samples.shape == (len(output.log_weights), 2)
    assert output.weights.sum() == pytest.approx(1.0)
    assert output.n_calls == likelihood.calls
    assert output.n_rejected == 0
    assert output.names == ("toy.x", "toy.y")
    assert output.settings == ACCURATE.to_dict()
    best = output.samples[np.argmax(output.log_likelihoods)]
    np.testing.assert_array_equal(output.max_likelihood(), best)
    lower, upper = output.credible_interval(1)
    assert np.all(lower < output.median())
    assert np.all(output.median() < upper)
    np.testing.assert_allclose(upper - lower, 2 * SIGMA, rtol=0.2)


def test_progress_is_quiet_plain_lines(static_run):
    _, output, lines = static_run
    assert lines[0].startswith("dynesty_static: 2 free parameters, seed 11")
    # progress_every is huge: one progress line at the start, then only the summary
    assert len(lines) == 3
    assert lines[-1].startswith("dynesty_static: done")
    assert f"{output.n_calls} calls" in lines[-1]
    assert not any("\r" in line for line in lines)


def test_progress_every_zero_logs_each_iteration():
    lines: list[str] = []
    settings = SamplerSettings(n_live=20, dlogz=5.0, progress_every=0.0)
    output = run_nested(GaussianLikelihood(), SPACE, settings, seed=2, log=lines.append)
    iterations = [line for line in lines if ": iteration " in line]
    # one line per dead point, then one per live point added at the end
    assert len(iterations) == len(output.samples)
    assert "ln Z = " in iterations[-1]
    assert "rejected" in iterations[-1]


@pytest.fixture(scope="module")
def fast_run():
    return run_nested(GaussianLikelihood(), SPACE, FAST, seed=11, log=lambda _: None)


def test_same_seed_same_run(fast_run):
    again = run_nested(GaussianLikelihood(), SPACE, FAST, seed=11, log=lambda _: None)
    np.testing.assert_array_equal(again.samples, fast_run.samples)
    assert again.log_evidence == fast_run.log_evidence


def test_max_iterations_caps_the_run_with_a_warning(fast_run):
    lines: list[str] = []
    capped = SamplerSettings(n_live=100, progress_every=1e9, max_iterations=50)
    output = run_nested(GaussianLikelihood(), SPACE, capped, seed=11, log=lines.append)
    # 50 dead points (dynesty stops after the 51st) plus the 100 final live points,
    # against ~1000 without the cap
    assert len(output.samples) in (150, 151)
    assert len(fast_run.samples) > 500
    assert any("WARNING stopped at max_iterations = 50" in line for line in lines)
    assert not output.converged
    assert output.stop_reason.startswith("stopped at max_iterations = 50 with remaining Δln Z")
    assert fast_run.converged
    assert fast_run.stop_reason.startswith("remaining Δln Z = ")
    assert fast_run.statistics()["converged"] is True
    with pytest.raises(ValueError, match="dynesty samplers only"):
        SamplerSettings(method="nautilus", max_iterations=10)
    with pytest.raises(ValueError, match="max_iterations must be an integer >= 1"):
        SamplerSettings(max_iterations=0)


@pytest.mark.parametrize(
    "settings",
    [
        SamplerSettings(n_live=100, progress_every=1e9, max_calls=300),
        SamplerSettings(
            method="nautilus", n_live=100, n_networks=1, progress_every=0, max_calls=300
        ),
    ],
    ids=["dynesty", "nautilus"],
)
def test_max_calls_caps_the_run_with_a_warning(settings):
    lines: list[str] = []
    likelihood = GaussianLikelihood()
    output = run_nested(likelihood, SPACE, settings, seed=11, log=lines.append)
    # dynesty stops at the first iteration past the cap (its 100 first live points are not
    # counted against it), nautilus after the batch (100 calls) that reaches it
    assert 300 <= output.n_calls == likelihood.calls <= 300 + 2 * 100
    assert any("WARNING stopped at max_calls = 300" in line for line in lines)
    assert not output.converged
    assert "stopped at max_calls = 300" in output.stop_reason
    assert output.statistics()["converged"] is False
    with pytest.raises(ValueError, match="max_calls must be an integer >= 1"):
        SamplerSettings(method=settings.method, max_calls=0)


def test_rejected_samples_are_counted():
    likelihood = GaussianLikelihood(reject_below=-2.0)
    output = run_nested(likelihood, SPACE, FAST, seed=5, log=lambda _: None)
    assert likelihood.rejected > 0
    assert output.n_rejected == likelihood.rejected
    assert output.n_calls == likelihood.calls
    rejected_samples = output.log_likelihoods == REJECTED_LOG_LIKELIHOOD
    assert np.all(output.weights[rejected_samples] == 0.0)
    # the rejected third of the prior carries no likelihood: ln Z is unchanged
    assert_recovers_gaussian(output)


def test_rejections_are_counted_across_a_pool(tmp_path):
    likelihood = GaussianLikelihood(reject_below=-2.0, marker_folder=tmp_path)
    settings = SamplerSettings(n_live=50, progress_every=1e9, n_processes=2)
    output = run_nested(likelihood, SPACE, settings, seed=5, log=lambda _: None)
    assert output.n_rejected == len(list(tmp_path.iterdir())) > 0
    assert likelihood.calls == 0  # every call ran in a worker
    assert_recovers_gaussian(output)


class WorkerPolicyProbe(GaussianLikelihood):
    """The Gaussian, rejecting every call made where a phase job's policy does not hold:
    more than one numba or BLAS thread, or freed work arrays page-faulted in again
    (mgelens.memory; the probe of tests/test_memory.py, once per process)."""

    checked = False

    def __call__(self, x: np.ndarray) -> float:
        if not self.checked:
            type(self).checked = True
            np.ones(1 << 17)  # a freed 1 MB array raises glibc's adaptive thresholds

            def round_trip():  # ten 512 kB work arrays, freed on return
                return len([np.ones(1 << 16) for _ in range(10)])

            round_trip()
            before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
            round_trip()
            type(self).faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
        if numba.get_num_threads() != 1 or blas_threads() != 1 or self.faults > 10:
            return REJECTED_LOG_LIKELIHOOD
        return super().__call__(x)


@pytest.mark.skipif(
    platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
    reason="mallopt thresholds are glibc's",
)
def test_pool_workers_run_one_thread_and_keep_freed_memory():
    """Spawned workers inherit neither the phase job's thread limits nor its malloc
    thresholds; the pool sets both, so two workers use two cores at full speed."""
    settings = SamplerSettings(n_live=50, progress_every=1e9, n_processes=2)
    likelihood = WorkerPolicyProbe()
    output = run_nested(likelihood, SPACE, settings, seed=5, log=lambda _: None)
    assert likelihood.calls == 0  # every call ran in a worker
    assert output.n_calls > 0
    assert output.n_rejected == 0


def test_resume_reproduces_the_uninterrupted_run(tmp_path, fast_run):
    reference = fast_run
    checkpoint = tmp_path / "sampler.pickle"
    settings = SamplerSettings(n_live=100, progress_every=1e9, checkpoint_every=0.1)
    with pytest.raises(Interrupted):  # once past half the calls and a checkpoint exists
        run_nested(
            GaussianLikelihood(stop_after=reference.n_calls // 2, stop_once_exists=checkpoint),
            SPACE,
            settings,
            checkpoint,
            seed=11,
            log=lambda _: None,
        )
    assert checkpoint.exists()
    lines: list[str] = []
    resumed = run_nested(GaussianLikelihood(), SPACE, settings, checkpoint, 11, lines.append)
    assert "resuming" in lines[0]
    np.testing.assert_array_equal(resumed.samples, reference.samples)
    np.testing.assert_array_equal(resumed.log_weights, reference.log_weights)
    assert resumed.log_evidence == reference.log_evidence
    assert resumed.log_evidence_error == reference.log_evidence_error
    assert (resumed.n_calls, resumed.n_rejected) == (reference.n_calls, reference.n_rejected)
    assert (resumed.n_resumes, reference.n_resumes) == (1, 0)

    # a finished checkpoint returns the stored run without sampling
    again = run_nested(failing_likelihood, SPACE, settings, checkpoint, 11, lambda _: None)
    assert again == resumed

    # a checkpoint of another fit is refused
    with pytest.raises(CheckpointMismatchError, match="seed"):
        run_nested(failing_likelihood, SPACE, settings, checkpoint, 12, lambda _: None)
    other = ParameterSpace.from_priors({"toy.x": Uniform(-4, 4), "toy.y": Uniform(-BOX, BOX)})
    with pytest.raises(CheckpointMismatchError, match="space"):
        run_nested(failing_likelihood, other, settings, checkpoint, 11, lambda _: None)


def test_a_checkpoint_is_checked_against_its_sidecar_before_it_is_read(tmp_path):
    checkpoint = tmp_path / "sampler.pickle"
    settings = SamplerSettings(n_live=20, progress_every=1e9, max_iterations=5)
    run_nested(GaussianLikelihood(), SPACE, settings, checkpoint, 11, lambda _: None)
    sidecar = tmp_path / "sampler.fingerprint.json"
    assert json.loads(sidecar.read_text())["seed"] == 11
    checkpoint.write_bytes(b"\x80\x04 not a pickle")  # e.g. planted or truncated
    with pytest.raises(CheckpointMismatchError, match="written for a different seed"):
        run_nested(failing_likelihood, SPACE, settings, checkpoint, 12, lambda _: None)
    with pytest.raises(CheckpointMismatchError, match=r"sampler\.pickle is unreadable"):
        run_nested(failing_likelihood, SPACE, settings, checkpoint, 11, lambda _: None)
    sidecar.unlink()
    with pytest.raises(CheckpointMismatchError, match=r"no sampler\.fingerprint\.json"):
        run_nested(failing_likelihood, SPACE, settings, checkpoint, 11, lambda _: None)


DYNAMIC = SamplerSettings(
    method="dynesty_dynamic", n_live=50, n_effective=400, progress_every=1e9, checkpoint_every=0.1
)


@pytest.fixture(scope="module")
def dynamic_run():
    likelihood = GaussianLikelihood()
    return likelihood, run_nested(likelihood, SPACE, DYNAMIC, seed=4, log=lambda _: None)


def test_dynamic_sampler_recovers_evidence(dynamic_run):
    likelihood, output = dynamic_run
    assert output.method == "dynesty_dynamic"
    assert output.n_calls == likelihood.calls
    assert_recovers_gaussian(output)


def test_dynamic_sampler_resumes(tmp_path, dynamic_run):
    _, reference = dynamic_run
    checkpoint = tmp_path / "sampler.pickle"
    # the batches start after ~92 % of the calls: stop during one
    stop = GaussianLikelihood(stop_after=int(0.95 * reference.n_calls), stop_once_exists=checkpoint)
    with pytest.raises(Interrupted):
        run_nested(stop, SPACE, DYNAMIC, checkpoint, seed=4, log=lambda _: None)
    resumed = run_nested(GaussianLikelihood(), SPACE, DYNAMIC, checkpoint, 4, lambda _: None)
    np.testing.assert_array_equal(resumed.samples, reference.samples)
    assert resumed.log_evidence == reference.log_evidence
    assert resumed.n_calls == reference.n_calls


def test_nautilus_recovers_evidence():
    settings = SamplerSettings(
        method="nautilus", n_live=100, n_networks=1, n_eff=200, progress_every=1e9
    )
    likelihood = GaussianLikelihood(reject_below=-2.0)
    output = run_nested(likelihood, SPACE, settings, seed=4, log=lambda _: None)
    assert output.n_calls == likelihood.calls
    assert output.n_rejected == likelihood.rejected > 0
    assert_recovers_gaussian(output, tolerance=0.15)


def test_nautilus_keeps_three_live_points_per_free_parameter():
    """Fewer live points than 3 per parameter are raised to that, logged and recorded;
    the quick MASS's 30 for its 8 parameters stand, and the 3×Sérsic MASS's 22 get 66."""
    settings = SamplerSettings(
        method="nautilus", n_live=4, n_networks=1, n_eff=100, progress_every=1e9
    )
    lines: list[str] = []
    output = run_nested(GaussianLikelihood(), SPACE, settings, seed=4, log=lines.append)
    assert output.settings["n_live"] == 6
    assert lines[0] == "nautilus: n_live raised from 4 to 6, 3 per free parameter (2)"
    assert abs(output.log_evidence - LOG_Z) < 0.5
    assert nautilus_live_points(30, 8) == 30
    assert nautilus_live_points(30, 22) == 66


NAUTILUS = SamplerSettings(
    method="nautilus", n_live=100, n_networks=1, n_eff=200, progress_every=1e9, checkpoint_every=0
)
"""A small nautilus run writing its checkpoint every second."""


def interrupted_nautilus(tmp_path, reference) -> Path:
    """The checkpoint of a nautilus run of the Gaussian killed past half its calls."""
    checkpoint = tmp_path / "sampler.pickle"
    written = checkpoint.with_suffix(".h5")  # nautilus's checkpoint
    stop = GaussianLikelihood(stop_after=reference.n_calls // 2, stop_once_exists=written)
    with pytest.raises(Interrupted):
        run_nested(stop, SPACE, NAUTILUS, checkpoint, seed=4, log=lambda _: None)
    assert written.exists()
    return checkpoint


def test_nautilus_resumes_to_the_uninterrupted_run(tmp_path):
    settings = NAUTILUS
    reference = run_nested(GaussianLikelihood(), SPACE, settings, seed=4, log=lambda _: None)
    checkpoint = interrupted_nautilus(tmp_path, reference)
    written = checkpoint.with_suffix(".h5")
    with h5py.File(written, "r") as stream:  # the interrupted session's own record
        interrupted = dict(stream["mgelens"].attrs)
    assert interrupted["n_resumes"] == 0
    assert interrupted["runtime"] > 0
    lines: list[str] = []
    likelihood = GaussianLikelihood()
    resumed = run_nested(likelihood, SPACE, settings, checkpoint, 4, lines.append)
    assert "seed 4, 0 calls so far" not in lines[0]  # it started from the checkpoint
    assert 0 < likelihood.calls < reference.n_calls  # only the rest was sampled
    np.testing.assert_array_equal(resumed.samples, reference.samples)
    np.testing.assert_array_equal(resumed.log_weights, reference.log_weights)
    assert resumed.log_evidence == reference.log_evidence
    assert resumed.n_calls == reference.n_calls
    assert (reference.n_resumes, resumed.n_resumes) == (0, 1)
    assert resumed.runtime > interrupted["runtime"]  # both sessions' seconds
    with h5py.File(written, "r+") as stream:  # as an mgelens without the record wrote it
        del stream["mgelens"]
    again = run_nested(failing_likelihood, SPACE, settings, checkpoint, 4, lambda _: None)
    assert again.n_calls == reference.n_calls  # the finished run, not sampled again
    assert again.n_resumes == 1
    with pytest.raises(CheckpointMismatchError, match="seed"):
        run_nested(failing_likelihood, SPACE, settings, checkpoint, 5, lambda _: None)
    written.with_suffix(".fingerprint.json").unlink()  # e.g. a copied or older folder
    with pytest.raises(CheckpointMismatchError, match=r"no sampler\.fingerprint\.json"):
        run_nested(failing_likelihood, SPACE, settings, checkpoint, 4, lambda _: None)


def test_nautilus_resumes_from_its_checkpoint_when_killed_while_writing(tmp_path, monkeypatch):
    """The checkpoint is written whole into a temporary file and renamed onto the old one
    (nautilus, left to itself, rewrote its file in place: a MASS run on M2 stopped in a
    write left one without its random state). A run killed in the middle of a checkpoint
    write keeps the previous checkpoint, and its resume reaches the uninterrupted run."""
    import nautilus

    reference = run_nested(GaussianLikelihood(), SPACE, NAUTILUS, seed=4, log=lambda _: None)
    checkpoint = tmp_path / "sampler.pickle"
    written = checkpoint.with_suffix(".h5")
    original = nautilus.Sampler.write

    def killed_in_second_write(sampler, filepath, overwrite=False):
        if written.exists():  # the first checkpoint is in place: die half way through
            with h5py.File(filepath, "w") as stream:
                stream.create_group("sampler").attrs["n_dim"] = 2
            raise Interrupted
        original(sampler, filepath, overwrite)

    monkeypatch.setattr(nautilus.Sampler, "write", killed_in_second_write)
    with pytest.raises(Interrupted):
        run_nested(GaussianLikelihood(), SPACE, NAUTILUS, checkpoint, seed=4, log=lambda _: None)
    monkeypatch.setattr(nautilus.Sampler, "write", original)
    with h5py.File(written, "r") as stream:  # the first checkpoint, whole
        assert "rng_state" in stream["sampler"].attrs
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "sampler.fingerprint.json",
        "sampler.h5",
    ]  # no half-written file left beside it
    likelihood = GaussianLikelihood()
    resumed = run_nested(likelihood, SPACE, NAUTILUS, checkpoint, 4, lambda _: None)
    assert 0 < likelihood.calls < reference.n_calls
    np.testing.assert_array_equal(resumed.samples, reference.samples)
    assert resumed.log_evidence == reference.log_evidence


def test_nautilus_networks_keep_loss_curves_its_checkpoint_can_hold(tmp_path):
    """Nautilus writes each network's loss curve (one float per epoch) as an HDF5
    attribute: at nautilus's default 10,000 epochs that attribute cannot be written, at
    the cap it can, and the cap reaches nautilus's networks."""
    with h5py.File(tmp_path / "limit.h5", "w") as stream:
        stream.attrs["loss_curve_0"] = np.zeros(NAUTILUS_NETWORK_MAX_ITER)
        with pytest.raises((RuntimeError, OSError), match="too large"):
            stream.attrs["loss_curve_1"] = np.zeros(10_000)
    checkpoint = tmp_path / "sampler.pickle"
    settings = dataclasses.replace(NAUTILUS, max_calls=400)
    run_nested(GaussianLikelihood(), SPACE, settings, checkpoint, 4, lambda _: None)
    with h5py.File(checkpoint.with_suffix(".h5"), "r") as stream:
        assert stream["sampler"].attrs["neural_network_max_iter"] == NAUTILUS_NETWORK_MAX_ITER


def test_sample_method_resolution():
    assert resolve_sample_method("auto", 8) == "unif"
    assert resolve_sample_method("auto", 17) == "rwalk"
    assert resolve_sample_method("auto", 21) == "rslice"
    assert resolve_sample_method("slice", 3) == "slice"


class PlateauFirst(GaussianLikelihood):
    """ln L = −3 for the first ``n_flat`` calls (a run whose first live points come from
    them stops on that plateau before its first dead point), the Gaussian after."""

    def __init__(self, n_flat, **options):
        super().__init__(**options)
        self.n_flat = n_flat

    def __call__(self, x: np.ndarray) -> float:
        value = super().__call__(x)
        return -3.0 if self.calls <= self.n_flat else value


PLATEAU = SamplerSettings(n_live=10, sample="rwalk", dlogz=0.5, progress_every=1e9)


def test_a_run_that_stops_on_a_plateau_restarts_with_twice_the_live_points():
    settings = dataclasses.replace(PLATEAU, plateau_restarts=2)
    lines: list[str] = []
    output = run_nested(PlateauFirst(n_flat=10), SPACE, settings, seed=3, log=lines.append)
    assert any("restart 1 of 2 after a likelihood plateau, with 20 live points" in x for x in lines)
    # the restart is a fresh run of 20 live points with the next seed on the Gaussian
    fresh = run_nested(
        GaussianLikelihood(),
        SPACE,
        dataclasses.replace(PLATEAU, n_live=20),
        seed=4,
        log=lambda _: None,
    )
    np.testing.assert_array_equal(output.samples, fresh.samples)
    assert output.log_evidence == fresh.log_evidence
    assert (output.settings["n_live"], output.seed) == (20, 4)
    assert output.converged
    assert output.n_calls == fresh.n_calls + 10
    assert "attempt 2 of 3, live points 10, 20" in output.stop_reason
    assert_recovers_gaussian(output)

    # without restarts the plateau is reported, not hidden
    alone = run_nested(PlateauFirst(n_flat=10), SPACE, PLATEAU, seed=3, log=lambda _: None)
    assert not alone.converged
    assert alone.stop_reason.startswith("stopped on a likelihood plateau")
    assert "Δln Z = inf" in alone.stop_reason  # stopped before its first dead point

    # a run that converges is not restarted
    plain = run_nested(GaussianLikelihood(), SPACE, PLATEAU, seed=3, log=lambda _: None)
    again = run_nested(GaussianLikelihood(), SPACE, settings, seed=3, log=lambda _: None)
    assert plain.converged
    assert again.n_calls == plain.n_calls
    np.testing.assert_array_equal(again.samples, plain.samples)


def test_restarts_that_all_stop_on_the_plateau_leave_the_run_unconverged():
    settings = dataclasses.replace(PLATEAU, plateau_restarts=2)
    output = run_nested(PlateauFirst(n_flat=10**9), SPACE, settings, seed=3, log=lambda _: None)
    assert not output.converged
    assert output.stop_reason.startswith("stopped on a likelihood plateau")
    assert "attempt 3 of 3, live points 10, 20, 40" in output.stop_reason
    assert output.n_calls == 10 + 20 + 40
    assert output.settings["n_live"] == 40


def test_an_interrupted_restart_resumes_from_its_own_checkpoint(tmp_path):
    checkpoint = tmp_path / "sampler.pickle"
    settings = dataclasses.replace(PLATEAU, plateau_restarts=1, checkpoint_every=0.0)
    reference = run_nested(PlateauFirst(n_flat=10), SPACE, settings, seed=3, log=lambda _: None)
    restart_checkpoint = tmp_path / "sampler-restart1.pickle"
    with pytest.raises(Interrupted):  # half-way through the restart
        run_nested(
            PlateauFirst(
                n_flat=10,
                stop_after=10 + reference.n_calls // 2,
                stop_once_exists=restart_checkpoint,
            ),
            SPACE,
            settings,
            checkpoint,
            seed=3,
            log=lambda _: None,
        )
    assert (tmp_path / "sampler-restart1.fingerprint.json").exists()
    lines: list[str] = []
    # the first attempt's finished checkpoint is not sampled again: every call is the
    # restart's, on the Gaussian
    resumed = run_nested(PlateauFirst(n_flat=0), SPACE, settings, checkpoint, 3, lines.append)
    assert sum("resuming" in line for line in lines) == 2
    np.testing.assert_array_equal(resumed.samples, reference.samples)
    assert resumed.log_evidence == reference.log_evidence
    assert resumed.n_calls == reference.n_calls
    assert resumed.n_resumes == 1


def test_settings_validation():
    with pytest.raises(ValueError, match="method"):
        SamplerSettings(method="multinest")
    with pytest.raises(ValueError, match="unknown sampler settings"):
        SamplerSettings.from_dict({"nlive": 100})
    assert SamplerSettings.from_dict(FAST.to_dict()) == FAST
    assert "n_processes" not in FAST.result_settings()
    with pytest.raises(ValueError, match="plateau_restarts applies to method dynesty_static"):
        SamplerSettings(method="nautilus", plateau_restarts=1)
    with pytest.raises(ValueError, match="plateau_restarts"):
        SamplerSettings(plateau_restarts=-1)


def test_nan_likelihood_is_an_error():
    def nan_likelihood(x):
        return math.nan

    with pytest.raises(FloatingPointError, match="return -1e"):
        run_nested(nan_likelihood, SPACE, FAST, log=lambda _: None)


def _run_of(samples: np.ndarray, log_evidence: float, error: float, calls: int) -> SamplerOutput:
    """A hand-made one-parameter run with equal weights."""
    n = len(samples)
    return SamplerOutput(
        names=("x",),
        samples=samples[:, None],
        log_weights=np.full(n, -math.log(n)) + 3.0,  # unnormalised on purpose
        log_likelihoods=-0.5 * samples**2,
        log_evidence=log_evidence,
        log_evidence_error=error,
        n_calls=calls,
        n_rejected=1,
        runtime=2.0,
        n_resumes=0,
        method="nautilus",
        settings={},
        seed=7,
    )


def test_pooled_runs_are_an_equal_weight_mixture_whatever_their_evidence_and_size():
    from scipy.optimize import brentq
    from scipy.stats import norm

    # exact quantile grids of N(0, 1) (2,001 samples) and N(4, 1) (20,001 samples)
    a = norm.ppf((np.arange(2001) + 0.5) / 2001)
    b = 4.0 + norm.ppf((np.arange(20001) + 0.5) / 20001)
    pooled = pool_runs([_run_of(a, -10.0, 0.3, 100), _run_of(b, -50.0, 0.4, 50)])
    weights = pooled.weights
    assert weights[:2001].sum() == pytest.approx(0.5, abs=1e-12)
    assert weights[2001:].sum() == pytest.approx(0.5, abs=1e-12)
    assert weights[0] == pytest.approx(20001 / 2001 * weights[-1])
    # the mixture 0.5 N(0, 1) + 0.5 N(4, 1): median 2, 3σ limits from its CDF
    assert pooled.median()[0] == pytest.approx(2.0, abs=0.01)
    lower, upper = pooled.credible_interval(3.0)
    p = (1 - math.erf(3 / math.sqrt(2))) / 2
    cdf = lambda x, q: 0.5 * norm.cdf(x) + 0.5 * norm.cdf(x - 4.0) - q  # noqa: E731
    assert lower[0] == pytest.approx(brentq(cdf, -10, 10, args=(p,)), abs=0.03)
    assert upper[0] == pytest.approx(brentq(cdf, -10, 10, args=(1 - p,)), abs=0.03)
    assert pooled.log_evidence == pytest.approx(-30.0)
    assert pooled.log_evidence_error == pytest.approx(math.hypot(0.5 / 2, 20.0))
    assert (pooled.n_calls, pooled.n_rejected, pooled.runtime) == (150, 2, 4.0)
    assert pooled.max_likelihood_index == int(np.argmin(np.abs(a)))


def test_pooling_checks_its_runs():
    run = _run_of(np.zeros(3), 0.0, 0.1, 1)
    assert pool_runs([run]) is run
    with pytest.raises(ValueError, match="no sampler runs"):
        pool_runs([])
    other = SamplerOutput(**{**run.__dict__, "names": ("y",)})
    with pytest.raises(ValueError, match="different parameters"):
        pool_runs([run, other])
    capped = SamplerOutput(**{**run.__dict__, "converged": False, "stop_reason": "capped"})
    pooled = pool_runs([run, capped])
    assert not pooled.converged
    assert "run 2: capped" in pooled.stop_reason


def bound_update_failing_at(monkeypatch, failing_call: int) -> dict:
    """Make dynesty's k-means split of the live points raise the IndexError that collapsed
    live points gave it in a real run (scipy's kmeans2 on a zero-spread coordinate), once,
    at its ``failing_call``-th use."""
    calls = {"n": 0}
    real = dynesty.bounding._bounding_ellipsoids

    def split(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == failing_call:
            raise IndexError("Out of bounds on buffer access (axis 0)")
        return real(*args, **kwargs)

    monkeypatch.setattr(dynesty.bounding, "_bounding_ellipsoids", split)
    return calls


def test_a_failed_bound_update_stops_the_run_like_a_plateau(monkeypatch):
    calls = bound_update_failing_at(monkeypatch, 3)
    lines: list[str] = []
    alone = run_nested(GaussianLikelihood(), SPACE, PLATEAU, seed=3, log=lines.append)
    assert calls["n"] == 3  # it stopped where the split failed
    assert not alone.converged
    assert alone.stop_reason.startswith("stopped on a likelihood plateau")
    assert "live points collapsed and dynesty's bound update failed" in alone.stop_reason
    assert any("WARNING stopped on a likelihood plateau" in line for line in lines)
    # what it sampled so far is kept, with the final live points
    assert alone.samples.shape[0] >= PLATEAU.n_live
    assert np.isfinite(alone.log_evidence)
    np.testing.assert_allclose(np.exp(alone.log_weights).sum(), 1.0)

    bound_update_failing_at(monkeypatch, 3)
    settings = dataclasses.replace(PLATEAU, plateau_restarts=1)
    restarted = run_nested(GaussianLikelihood(), SPACE, settings, seed=3, log=lambda _: None)
    fresh = run_nested(  # the restart: 20 live points, the next seed, no failure
        GaussianLikelihood(),
        SPACE,
        dataclasses.replace(PLATEAU, n_live=20),
        seed=4,
        log=lambda _: None,
    )
    assert restarted.converged
    assert "attempt 2 of 2, live points 10, 20" in restarted.stop_reason
    np.testing.assert_array_equal(restarted.samples, fresh.samples)


def test_an_index_error_from_elsewhere_is_not_taken_for_a_collapse():
    class Broken(GaussianLikelihood):
        def __call__(self, x):
            if self.calls > 30:
                raise IndexError("a bug in the likelihood")
            return super().__call__(x)

    with pytest.raises(IndexError, match="a bug in the likelihood"):
        run_nested(Broken(), SPACE, PLATEAU, seed=3, log=lambda _: None)
