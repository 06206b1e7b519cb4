"""``mgelens simulate``: write one mock lens folder (SPEC §10).

Examples::

    mgelens simulate --mock M1 --out results/M1/mock
    mgelens simulate --mock M2 --noise-seed 11 --name M2n11 --out results/M2n11/mock
    mgelens simulate --population-index 7 --population-seed 2024 --out results/P07/mock
    mgelens simulate --mock M3 --source-image ngc3690.fits --source-pixel-scale 0.004 --out m3

The folder receives ``data.fits``, ``noise_map.fits``, ``psf.fits`` (the layout of the real
SLACS folders), the noise-free truth images and ``truth.json``
(:data:`mgelens.simulate.MOCK_FILES`).
"""

import argparse
import dataclasses
import logging
import time

from mgelens import simulate
from mgelens.commands import add_threads_argument
from mgelens.threads import limit_threads

logger = logging.getLogger("mgelens.simulate")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="simulate a mock lens (paper mock M1-M3 or a population lens)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    recipe = parser.add_mutually_exclusive_group(required=True)
    recipe.add_argument(
        "--mock", choices=sorted(simulate.PAPER_MOCKS), help="one of the paper's mocks"
    )
    recipe.add_argument(
        "--population-index", type=int, metavar="I", help="lens I of the mock population"
    )
    parser.add_argument(
        "--population-seed",
        type=int,
        default=simulate.DEFAULT_POPULATION_SEED,
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


def build_lens(args: argparse.Namespace) -> simulate.MockLens:
    """The :class:`~mgelens.simulate.MockLens` described by the parsed arguments."""
    if args.mock is not None:
        lens = simulate.paper_mock(args.mock, seed=args.seed, noise_seed=args.noise_seed)
    else:
        for option, value in (("--seed", args.seed), ("--noise-seed", args.noise_seed)):
            if value is not None:
                raise ValueError(
                    f"{option} applies to paper mocks only; population lenses derive their "
                    "seeds from --population-seed and --population-index"
                )
        lens = simulate.population_lens(args.population_index, args.population_seed)
    if (args.source_image is None) != (args.source_pixel_scale is None):
        raise ValueError("--source-image and --source-pixel-scale must be given together")
    if args.source_image is not None:
        pixels = simulate.load_source_image(args.source_image)
        lens = simulate.with_image_source(
            lens, pixels, args.source_pixel_scale, path=args.source_image
        )
    if args.name:
        lens = dataclasses.replace(lens, name=args.name)
    return lens


def run(args: argparse.Namespace) -> int:
    try:
        limit_threads(args.threads)
        observation = simulate.Observation(image_size=args.image_size, sub_size=args.sub_size)
        lens = build_lens(args)
        start = time.perf_counter()
        mock = simulate.simulate(lens, observation)
        folder = simulate.write_mock(mock, args.out)
    except (ValueError, OSError) as error:
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
