"""Settings of the non-linear search (SPEC §8.3): which sampler, and how it runs.

:class:`SamplerSettings` is a frozen, validated record with no numerics behind it, so that
configuration (:mod:`mgelens.pipeline.settings`, the workflow's DAG parse) can read and
check it without loading the samplers; :func:`mgelens.search.sampler.run_nested` runs it.
"""

from dataclasses import asdict, dataclass, fields

from mgelens import values

METHODS = ("dynesty_static", "dynesty_dynamic", "nautilus")
"""The samplers :func:`mgelens.search.sampler.run_nested` runs."""


@dataclass(frozen=True)
class SamplerSettings:
    """Settings of the non-linear search (defaults: SPEC §8.3, anchor ``nest.yaml``).

    Attributes
    ----------
    method : {"dynesty_static", "dynesty_dynamic", "nautilus"}
    n_live : int
        Live points (dynesty ``nlive``; for the dynamic sampler both the baseline and the
        batches; nautilus ``n_live``).
    dlogz : float or None
        dynesty stopping criterion on the remaining log evidence; ``None`` uses dynesty's
        default (static: 1e-3 (n_live − 1) + 0.01; dynamic baseline: 0.01).
    bound, sample : str
        dynesty bounding and sampling methods. ``sample="auto"`` is resolved here with
        dynesty's rule (unif below 10 dimensions, rwalk up to 20, rslice above) so that
        ``walks``/``slices`` below apply (dynesty 3.1's own "auto" ignores them).
    walks, slices : int
        Steps of the rwalk sampler and slice updates of the (r)slice samplers.
    facc : float
        Target acceptance fraction of rwalk.
    n_effective : int or None
        Dynamic sampler: target effective sample size (dynesty default if ``None``).
    max_iterations : int or None
        dynesty only: stop after this many iterations even if ``dlogz`` is not reached
        (dynesty ``maxiter``; a warning is logged). For smoke tests and hard time limits;
        the posterior of a capped run is not converged.
    max_calls : int or None
        Stop after this many likelihood calls, counted over the whole run including
        resumed sessions (nautilus ``n_like_max``, dynesty ``maxcall``), with a warning;
        as ``max_iterations``, for smoke tests.
    enlarge_per_dim, split_threshold, n_networks, n_batch, f_live, n_shell, n_eff, \
discard_exploration
        Nautilus settings (SPEC §8.3).
    checkpoint_every : float
        Seconds between checkpoints (dynesty).
    progress_every : float
        Seconds between progress lines (nautilus: at least 1 s).
    n_processes : int
        Likelihood processes; 1 = no pool.
    queue_size : int or None
        dynesty proposals evaluated in parallel (default: ``n_processes``).
    plateau_restarts : int
        Static dynesty only: how many times a run that stops on a likelihood plateau (every
        live point at one ln L, short of ``dlogz`` and of the caps) is started afresh with
        twice the live points and the next seed. Random walks that cannot leave a narrow
        spike of ln L return copies of it until every live point is that copy; more live
        points make that rarer. A run whose bound update fails on such copies counts as
        one that stopped on a plateau (``sampler.COLLAPSED_STOP``). Each attempt has its
        own checkpoint (``<stem>-restart<k>``) and its own caps; the output is the last
        attempt's (samples, settings, seed), with the calls, runtimes and resumes of all
        attempts summed and the restarts named in its stop reason.
    peak_restarts : int
        0: no check. Otherwise, after a run (any method) that converged, a local search
        from its highest-posterior sample (:func:`mgelens.search.peak_check.peak_gain`,
        at most ``peak_evaluations`` calls; none if that is 0) checks that the posterior
        holds the peak of ln L + ln prior (an unconverged run, capped or on a plateau, is
        reported as such, unchecked), and so does the ``reference`` point given to
        :func:`~mgelens.search.sampler.run_nested` (SP's start) if it lies inside the
        priors' support: the run's peak gain is the larger of the search's gain and the
        reference's ln L above the run's highest (with neither, the run is not checked).
        If it exceeds ``peak_tolerance``, the run is started afresh with twice the live
        points and the next seed (own checkpoint ``<stem>-peak<k>``), up to this many
        times; a restart's gain is at least how far its highest ln L + ln prior falls
        below the earlier attempts'. The output is the last attempt's, with every
        attempt's calls (and the checks') summed and ``peak_gain`` recorded; one that
        still misses its peak is not converged.
    peak_tolerance : float
        ln L a check may gain before the run counts as missing its peak.
    peak_evaluations : int
        Likelihood calls of one check's local search (about); 0: no local search, the
        reference point alone is checked.
    reference_live_point : bool
        Static dynesty only: the ``reference`` point given to
        :func:`~mgelens.search.sampler.run_nested` (SP's start), if it lies inside the
        priors' support, replaces the lowest-likelihood point of every run's first live
        points (restarts' too), which are otherwise drawn from the prior as dynesty draws
        them. A live point leaves the set only as its lowest, so the run's highest ln L is
        at least the reference's, and walks started from it climb its peak where the
        prior's draws alone settle in a lower mode. One point of n_live is not drawn from
        the prior, so the run's ln Z is not the prior's evidence (docs/slam.md): for a phase
        that hands on its maximum-likelihood model, as SP does; SPEC §8.3 draws every
        point from the prior. Off in both profiles
        (``slam: {samplers: {sp: {reference_live_point: true}}}`` turns it on for SP).

    The fields from ``checkpoint_every`` on change only how a run is executed, not its
    result, except that a pool (``n_processes > 1``) changes both samplers' random
    streams: dynesty draws its proposals in queues of ``queue_size``, nautilus trains its
    networks in the pool, so the samples differ from one process's with the same seed.
    """

    method: str = "dynesty_static"
    n_live: int = 200
    dlogz: float | None = None
    bound: str = "multi"
    sample: str = "auto"
    walks: int = 5
    slices: int = 5
    facc: float = 0.2
    n_effective: int | None = None
    max_iterations: int | None = None
    max_calls: int | None = None
    enlarge_per_dim: float = 1.1
    split_threshold: float = 100.0
    n_networks: int = 4
    n_batch: int = 100
    f_live: float = 0.01
    n_shell: int = 1
    n_eff: int = 500
    discard_exploration: bool = False
    checkpoint_every: float = 60.0
    progress_every: float = 60.0
    n_processes: int = 1
    queue_size: int | None = None
    plateau_restarts: int = 0
    peak_restarts: int = 0
    peak_tolerance: float = 2.0
    peak_evaluations: int = 400
    reference_live_point: bool = False

    def __post_init__(self):
        """Check every field's type and range; a ValueError starts with the field's name."""
        values.choice("method", self.method, METHODS)
        values.choice("bound", self.bound, BOUNDS)
        values.choice("sample", self.sample, SAMPLE_METHODS)
        for name, minimum in _INTEGER_FIELDS.items():
            value = getattr(self, name)
            if not (value is None and name in _OPTIONAL_FIELDS):
                values.integer(name, value, minimum)
        for name, limits in _NUMBER_FIELDS.items():
            value = getattr(self, name)
            if not (value is None and name in _OPTIONAL_FIELDS):
                values.number(name, value, **limits)
        values.boolean("discard_exploration", self.discard_exploration)
        values.boolean("reference_live_point", self.reference_live_point)
        if self.reference_live_point and self.method != "dynesty_static":
            raise ValueError(
                f"reference_live_point applies to method dynesty_static only, not to {self.method}"
            )
        if self.max_iterations is not None and self.method == "nautilus":
            raise ValueError("max_iterations applies to the dynesty samplers only")
        if self.plateau_restarts and self.method != "dynesty_static":
            raise ValueError(
                "plateau_restarts applies to method dynesty_static only (the others do not "
                f"stop on a likelihood plateau), not to {self.method}"
            )

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, content: dict) -> "SamplerSettings":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(content) - known)
        if unknown:
            raise ValueError(
                f"{unknown[0]}: unknown sampler settings {unknown}; known: {sorted(known)}"
            )
        return cls(**content)

    def result_settings(self) -> dict:
        """The settings that determine the result (all but the execution fields)."""
        execution = ("checkpoint_every", "progress_every", "n_processes")
        return {k: v for k, v in self.to_dict().items() if k not in execution}


BOUNDS = ("none", "single", "multi", "balls", "cubes")
"""dynesty's bounding methods."""
SAMPLE_METHODS = ("auto", "unif", "rwalk", "slice", "rslice")
"""dynesty's sampling methods ("auto": :func:`mgelens.search.sampler.resolve_sample_method`)."""
_INTEGER_FIELDS = {
    "n_live": 2,
    "walks": 1,
    "slices": 1,
    "n_effective": 1,
    "max_iterations": 1,
    "max_calls": 1,
    "n_networks": 1,
    "n_batch": 1,
    "n_shell": 1,
    "n_processes": 1,
    "queue_size": 1,
    "plateau_restarts": 0,
    "peak_restarts": 0,
    "peak_evaluations": 0,
}
"""Integer settings and their minimum."""
_NUMBER_FIELDS = {
    "dlogz": {"minimum": 0.0, "open_minimum": True},
    "facc": {"minimum": 0.0, "maximum": 1.0, "open_minimum": True},
    "enlarge_per_dim": {"minimum": 1.0},
    "split_threshold": {"minimum": 0.0, "open_minimum": True},
    "f_live": {"minimum": 0.0, "maximum": 1.0, "open_minimum": True},
    "n_eff": {"minimum": 0.0},
    "checkpoint_every": {"minimum": 0.0},
    "progress_every": {"minimum": 0.0},
    "peak_tolerance": {"minimum": 0.0, "open_minimum": True},
}
"""Real-valued settings and their range (:func:`mgelens.values.number`)."""
_OPTIONAL_FIELDS = ("dlogz", "n_effective", "max_iterations", "max_calls", "queue_size")
"""Settings that may be ``None`` (dynesty's default, or no cap)."""
