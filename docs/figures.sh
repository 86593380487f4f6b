#!/bin/sh
# Remakes the README's figures (tests/test_docs_commands.py checks that every PNG in docs/ is
# made here and that the goniolab commands below parse):
#   sh docs/figures.sh        (from the repository root, with .venv's goniolab and python on
#                              the PATH: source .venv/bin/activate)
# - docs/plot-example.png: a scan on the simulated lab, in a store of its own in a temporary
#   directory, plotted;
# - docs/render-example.png: left a silver metallic panel, right a pearl sphere, 256 x 256
#   each, both with the flakes' mean (--no-sparkle; the default draws each pixel's flakes).
set -eu
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
goniolab scan --config configs/lab-sim.toml --sample sample:wittmann-3 --theta-i 45 \
    --theta-r 0:70:1 --repeats 3 --time-scale 0 --store "$tmp/runs.sqlite" > /dev/null
goniolab plot 1 --store "$tmp/runs.sqlite" --out docs/plot-example.png
goniolab render sample:silver-metallic --out "$tmp/panel.png" --size 256 --lamps 2 \
    --exposure 0.5 --no-sparkle > /dev/null
goniolab render sample:pearl --out "$tmp/sphere.png" --size 256 --shape sphere --lamps 2 \
    --no-sparkle > /dev/null
python - "$tmp/panel.png" "$tmp/sphere.png" docs/render-example.png <<'EOF'
import sys
from PIL import Image

left, right = (Image.open(p).convert("RGB") for p in sys.argv[1:3])
both = Image.new("RGB", (left.width + right.width, max(left.height, right.height)))
both.paste(left, (0, 0))
both.paste(right, (left.width, 0))
both.save(sys.argv[3])
EOF
