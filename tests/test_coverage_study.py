"""The saved coverage study holds together and meets the issue's targets (issue #30).

A mock's chain takes about 18 minutes of a core, so the suite checks the rows that
``mgelens coverage`` wrote for the mocks fitted so far, saved in
``docs/coverage/coverage_lenses.csv`` (how they were made: docs/coverage.md, "The
saved study"), rather than fitting them again. A target the saved study misses is a
strict xfail whose reason gives the measured fraction, so that meeting it, or a new
study that misses another, fails the suite until the table and this file agree. Three
studies are saved: the paper's model (``source_support: mask``, the quick profile's
default until 2026-12-02) and the mocks fitted again with the arcs' support since, and
some of the latter fitted once more with 1,000 source pixels.
"""

import functools

import numpy as np
import pandas as pd
import pytest
from workflow_run import ROOT

from mgelens.coverage import PARAMETERS, ROW_COLUMNS, TARGETS, coverage_table, target_table
from mgelens.quality import NO_FLAG

SAVED = ROOT / "docs" / "coverage" / "coverage_lenses.csv"
SAVED_ARCS = ROOT / "docs" / "coverage" / "coverage_lenses_arcs.csv"
"""The mocks fitted again with the quick profile's default since 2026-12-02, the arcs'
source support (docs/coverage.md, "The study under the arcs' support")."""

MISSED = {
    "γ inside 3σ": (
        "0.905 of 21 mocks: L04's γ 2.549 (2.397–2.720) for 2.375, "
        "P01's 1.950 (1.904–2.024) for 2.027"
    ),
    "θ_E inside 3σ": (
        "0.905 of 21: P01's θ_E 0.8889″ (0.8823–0.8983) for 0.8984″, "
        "P07's 1.2991″ (1.2979–1.3005) for 1.3012″"
    ),
    "|median γ − truth| < 0.05": (
        "0.762 of 21: L00 −0.086, L02 +0.073, L04 +0.173, L05 −0.119, P01 −0.077"
    ),
    "θ_E within 1 %": "0.857 of 21: L00 −1.49 %, L02 +1.001 %, P01 −1.06 %",
}
"""Targets the saved study does not meet: target name → the measured numbers
(docs/coverage.md, "The saved study")."""

MISSED_ARCS = {
    "γ inside 3σ": (
        "0.872 of 47: P20's γ 2.578 (2.429–2.617) for 2.113 (SP's start misread the arcs' "
        "radius and SPix1's rescan moved to a wrong mass), P22's 1.943 (1.923–1.969) for "
        "1.978, P32's 2.111 (2.093–2.135) for 2.200 and P37's 2.249 (2.225–2.275) for 2.331 "
        "(slope–shear trades; MASS's likelihood at 500 source pixels prefers P22's and P32's "
        "to the truth by 57 and 80), P26's 2.093 (2.064–2.125) for 2.130, "
        "P36's 1.999 (1.939–2.070) for 2.071"
    ),
    "θ_E inside 3σ": (
        "0.872 of 47: P00's θ_E 1.0058″ (1.0007–1.0110) for 1.0114″, "
        "P01's 0.8939″ (0.8903–0.8982) for 0.8984″, P03's 0.9449″ (0.9405–0.9489) for 0.9400″, "
        "P20's 0.5238″ (0.4592–0.5829) for 0.8503″, P32's 1.3660″ (1.3610–1.3730) for 1.3859″, "
        "P37's 1.2397″ (1.2327–1.2488) for 1.2594″"
    ),
    "γ₁ inside 3σ": (
        "0.936 of 47: P20's γ₁ −0.085 (−0.106 to −0.058) for −0.052, "
        "P22's 0.058 (0.055–0.062) for 0.067, P32's −0.0200 (−0.0221 to −0.0175) for −0.0152"
    ),
    "γ₂ inside 3σ": (
        "0.915 of 47: P22's γ₂ −0.0527 (−0.0579 to −0.0477) for −0.0587, "
        "P30's −0.06179 (−0.06343 to −0.06041) for −0.06036, "
        "P32's −0.0386 (−0.0405 to −0.0365) for −0.0327, "
        "P37's 0.0170 (0.0131–0.0205) for 0.0274"
    ),
    "θ_E within 1 %": "0.915 of 47: P20 −38.4 %, P32 −1.44 %, P33 −1.32 %, P37 −1.56 %",
}
"""Targets the study under the arcs' support does not meet over its forty-seven mocks."""

SAVED_1000 = ROOT / "docs" / "coverage" / "coverage_lenses_arcs_1000.csv"
"""Mocks of the arcs' study fitted again from SPix2 on with 1,000 source pixels, the 3.0″
samples' value since 2026-12-05: three whose γ missed at 500 pixels (P32, P36, P37), one
whose γ₂ missed (P30), one whose θ_E missed 1 % (P33) and five that held (P27, P28, P29,
P31, P35); and P26 (γ and centre_y missed at 500), P22 (γ and the shear missed at 500),
P25 (fitted again whole on 2026-12-06 with the code of the rows after it), P21, P24 and
P23 (held at 500), P20 (a wrong basin at 500) and the independent mocks L00 (held at
500, θ_E −1.5 %), L01, L06, L02, L03, L04 (γ missed at 500), L07 (the issue's first
failure), L08 and L05, and the population mock P00, fitted whole at 1,000
(docs/coverage.md, "Compact clumps under 500 source pixels" and "The pixel count chosen
by SPix2's evidence"), and P01, P02, P04, P03, P06 and P10, fitted whole with the quick
profile of 2026-12-06, and P07, P09, P11–P19, P34 and L09–L11, fitted whole with the tuned
second mesh of 2026-12-07, and P08 and P05, fitted whole with the quick profile of
2026-12-07 (P05's SPix1 rescan with its θ_E-held polishes), which complete the study's
fifty. The rows of L00–L08, P00, P22–P25 are their MASS sampled
again with the adaptive signals held at SPix2's mass, the quick profile's since
2026-12-06 (docs/coverage.md, "The adaptive signals as a mass prior"). The rows of L00–L03,
L06–L08, P00–P04, P06, P10 and P22–P25 pool their saved seed-0 mesh's run with a run on the
seed-1 mesh whose hyper-parameters were searched on it, the quick profile's since
2026-12-07 (docs/coverage.md, "Each mesh its own hyper-parameters"). The first eleven
were chosen by their 500-pixel outcome, so its fractions compare the two resolutions
more than they measure a population's coverage."""

MISSED_1000 = {
    "θ_E inside 3σ": (
        "0.940 of 50: P20's θ_E 0.382 (0.351–0.551) for 0.850, "
        "L02's 1.6156 (1.6052–1.6321) for 1.5977, P15's 0.9908 (0.9852–0.9971) for 1.0001"
    ),
    "θ_E within 1 %": "0.920 of 50: P37 −1.31 %, P20 −55.1 %, L00 −1.81 %, L02 +1.12 %",
}
"""Targets the 1,000-pixel rows do not meet."""

MISSED_1000_UNFLAGGED = {
    "γ inside 3σ": (
        "0.946 of 37: L02's γ 2.335 (2.283–2.411) for 2.254, P15's 2.063 (2.031–2.094) for 2.112"
    ),
    "θ_E inside 3σ": "0.946 of 37: L02 +1.12 %, P15 −0.93 %",
    "θ_E within 1 %": "0.946 of 37: L00 −1.81 %, L02 +1.12 %",
}
"""Targets the 1,000-pixel fits that no quality check flags do not meet. The saved rows
carry ``flags`` (``mgelens quality`` on the chain's MASS result) for the mocks whose
results were on the machine when the column was added (L00–L03, L06, P20, P22–P24)
and the mocks fitted since (L04, L05, L07, L08, P00, P01, P02, P04, P03, P06, P10, P25
fitted again, P07, P09, P11–P19, P34 and L09–L11, and P05 and P08); the others' are
unknown and they are left out here."""

STUDIES = {
    "paper model": (SAVED, MISSED),
    "arcs' support": (SAVED_ARCS, MISSED_ARCS),
    "1,000 source pixels": (SAVED_1000, MISSED_1000),
    "1,000 source pixels, unflagged": (SAVED_1000, MISSED_1000_UNFLAGGED),
}


@functools.cache
def _saved(path) -> pd.DataFrame:
    if not path.is_file():
        pytest.skip(f"{path} not saved: see docs/coverage.md")
    return pd.read_csv(path)


def _study_rows(study: str) -> pd.DataFrame:
    """The saved rows of a study; those of the mocks no check flags for an "unflagged" one."""
    rows = _saved(STUDIES[study][0])
    return rows[rows["flags"] == NO_FLAG] if study.endswith("unflagged") else rows


@pytest.fixture(scope="module", params=list(STUDIES))
def rows(request) -> pd.DataFrame:
    return _study_rows(request.param)


def test_the_saved_rows_are_whole_mocks_of_the_study_sheet(rows):
    assert list(rows.columns)[: len(ROW_COLUMNS) + 1] == [*ROW_COLUMNS, "chain_seconds"]
    assert set(rows.columns[len(ROW_COLUMNS) + 1 :]) <= {"flags", "chain_cpu_seconds"}
    sheet = pd.read_csv(ROOT / "config" / "coverage.tsv", sep="\t", comment="#")
    assert set(rows["lens"]) <= set(sheet["lens"])
    for lens, part in rows.groupby("lens"):
        assert sorted(part["parameter"]) == sorted(PARAMETERS), lens
    assert (rows.groupby("lens")["chain_seconds"].first() > 0).all()


def test_the_saved_flags_and_errors_follow_from_the_intervals(rows):
    linear = rows[rows["parameter"] != "mass.angle"]
    assert np.allclose(linear["error"], linear["median"] - linear["truth"], atol=1e-12)
    for sigma in ("1sigma", "3sigma"):
        inside = (linear[f"lower_{sigma}"] <= linear["truth"]) & (
            linear["truth"] <= linear[f"upper_{sigma}"]
        )
        assert (inside == linear[f"within_{sigma}"].astype(bool)).all(), sigma
    angle = rows[rows["parameter"] == "mass.angle"]
    assert (angle["error"].abs() <= 90.0).all()


def test_the_saved_fractions_are_those_of_its_rows(rows):
    table = coverage_table(rows).set_index("parameter")
    assert list(table.index) == list(PARAMETERS)
    n = rows["lens"].nunique()
    assert (table["n"] == n).all()
    slope = rows[rows["parameter"] == "mass.slope"]
    assert table.loc["mass.slope", "within_3sigma"] == pytest.approx(
        slope["within_3sigma"].astype(bool).mean()
    )


@pytest.mark.parametrize(
    ("study", "target"),
    [
        pytest.param(
            study,
            t,
            marks=pytest.mark.xfail(strict=True, reason=missed[t.name]),
            id=f"{study}-{t.parameter}-{t.condition}",
        )
        if t.name in missed
        else pytest.param(study, t, id=f"{study}-{t.parameter}-{t.condition}")
        for study, (_, missed) in STUDIES.items()
        for t in TARGETS
    ],
)
def test_the_saved_study_meets_the_target(study, target):
    result = target_table(_study_rows(study), [target]).iloc[0]
    assert result["met"], f"{study}, {target.name}: {result['fraction']:.3f} of {result['n']} mocks"
