"""``mgelens simulate``: write one mock lens folder (SPEC §10).

Examples::

    mgelens simulate --mock M1 --out results/M1/mock
    mgelens simulate --mock M2 --noise-seed 11 --name M2n11 --out results/M2n11/mock
    mgelens simulate --population-index 7 --population-seed 2024 --out results/P07/mock
    mgelens simulate --independent-index 3 --image-size 201 --out results/L03/mock
    mgelens simulate --mock M3 --source-image ngc3690.fits --source-pixel-scale 0.004 --out m3

Independent mocks (:mod:`mgelens.independent_mock`) have their images formed by
lenstronomy, in the same layout and truth conventions; they need the ``independent``
extra.

The folder receives ``data.fits``, ``noise_map.fits``, ``psf.fits`` (the layout of the real
SLACS folders), the noise-free truth images and ``truth.json``
(:data:`mgelens.simulate.MOCK_FILES`).
"""

import argparse
import dataclasses
import logging
import time

from mgelens import mock_lenses, mock_sources, simulate
from mgelens.commands import add_threads_argument
from mgelens.independent_mock import (
    IndependentLens,
    MissingDependency,
    independent_lens,
    simulate_independent,
)
from mgelens.threads import limit_threads

logger = logging.getLogger("mgelens.simulate")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="simulate a mock lens (paper mock M1-M3, a population lens or an independent mock)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    recipe = parser.add_mutually_exclusive_group(required=True)
    recipe.add_argument(
        "--mock", choices=sorted(mock_lenses.PAPER_MOCKS), help="one of the paper's mocks"
    )
    recipe.add_argument(
        "--population-index", type=int, metavar="I", help="lens I of the mock population"
    )
    recipe.add_argument(
        "--independent-index",
        type=int,
        metavar="I",
        help="independent mock I, its images formed by lenstronomy (extra 'independent')",
    )
    parser.add_argument(
        "--population-seed",
        type=int,
        default=mock_lenses.DEFAULT_POPULATION_SEED,
        metavar="S",
        help="seed of the mock population (default %(default)s)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        metavar="N",
        help="seed of a paper mock (default 1, 2, 3 for M1, M2, M3): noise and source",
    )
    parser.add_argument(
        "--noise-seed",
        type=int,
        metavar="N",
        help="seed of a paper mock's noise alone (default: the seed): the same lens and "
        "source under another Poisson realisation",
    )
    parser.add_argument(
        "--source-image", metavar="FILE", help="use this .fits/.npy image as the source"
    )
    parser.add_argument(
        "--source-pixel-scale",
        type=float,
        metavar="X",
        help="arcsec per pixel of --source-image (required with it)",
    )
    parser.add_argument("--name", help="name recorded in the files (default: the mock's)")
    defaults = simulate.Observation()
    parser.add_argument(
        "--image-size",
        type=int,
        default=defaults.image_size,
        metavar="N",
        help="image is N x N pixels, odd (default %(default)s)",
    )
    parser.add_argument(
        "--sub-size",
        type=int,
        default=defaults.sub_size,
        metavar="S",
        help="S x S sub-pixels per pixel for lens light and source (default %(default)s)",
    )
    add_threads_argument(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.set_defaults(func=run)


def build_lens(args: argparse.Namespace) -> mock_lenses.MockLens | IndependentLens:
    """The mock lens described by the parsed arguments: a
    :class:`~mgelens.mock_lenses.MockLens` or an independent mock's
    :class:`~mgelens.independent_mock.IndependentLens`."""
    if args.independent_index is not None:
        return _independent_lens(args)
    if args.mock is not None:
        lens = mock_lenses.paper_mock(args.mock, seed=args.seed, noise_seed=args.noise_seed)
    else:
        for option, value in (("--seed", args.seed), ("--noise-seed", args.noise_seed)):
            if value is not None:
                raise ValueError(
                    f"{option} applies to paper mocks only; population lenses derive their "
                    "seeds from --population-seed and --population-index"
                )
        lens = mock_lenses.population_lens(args.population_index, args.population_seed)
    if (args.source_image is None) != (args.source_pixel_scale is None):
        raise ValueError("--source-image and --source-pixel-scale must be given together")
    if args.source_image is not None:
        pixels = mock_sources.load_source_image(args.source_image)
        lens = mock_lenses.with_image_source(
            lens, pixels, args.source_pixel_scale, path=args.source_image
        )
    if args.name:
        lens = dataclasses.replace(lens, name=args.name)
    return lens


def _independent_lens(args: argparse.Namespace) -> IndependentLens:
    for option, value in (
        ("--seed", args.seed),
        ("--noise-seed", args.noise_seed),
        ("--source-image", args.source_image),
    ):
        if value is not None:
            raise ValueError(
                f"{option} does not apply to independent mocks; they derive everything from "
                "--population-seed and --independent-index"
            )
    lens = independent_lens(args.independent_index, args.population_seed)
    return dataclasses.replace(lens, name=args.name) if args.name else lens


def run(args: argparse.Namespace) -> int:
    try:
        limit_threads(args.threads)
        observation = simulate.Observation(image_size=args.image_size, sub_size=args.sub_size)
        lens = build_lens(args)
        start = time.perf_counter()
        if isinstance(lens, IndependentLens):
            mock = simulate_independent(lens, observation)
        else:
            mock = simulate.simulate(lens, observation)
        folder = simulate.write_mock(mock, args.out)
    except (ValueError, OSError, MissingDependency) as error:
        logger.error("%s", error)
        return 1
    logger.info(
        "%s: %s written to %s in %.1f s (source S/N %.2f, source amplitude %.4g)",
        lens.name,
        ", ".join(simulate.MOCK_FILES.values()),
        folder,
        time.perf_counter() - start,
        mock.truth["signal_to_noise"]["source_max"],
        mock.truth["source"]["amplitude"],
    )
    return 0
