#!/bin/sh
# Remakes docs/plot-example.png (the README's plot figure) on the simulated lab:
#   sh docs/figures.sh        (from the repository root, with .venv's goniolab on the PATH)
# The run goes into a store of its own in a temporary directory.
set -eu
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
goniolab scan --config configs/lab-sim.toml --sample sample:wittmann-3 --theta-i 45 \
    --theta-r 0:70:1 --repeats 3 --time-scale 0 --store "$tmp/runs.sqlite" > /dev/null
goniolab plot 1 --store "$tmp/runs.sqlite" --out docs/plot-example.png
