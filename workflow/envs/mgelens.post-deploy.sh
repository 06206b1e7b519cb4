#!/usr/bin/env bash
# Run by Snakemake inside the new conda environment of mgelens.yaml: install mgelens from
# this repository (two levels above this script), without touching the conda packages.
set -euo pipefail
pip install --no-deps -e "$(dirname "$0")/../.."
