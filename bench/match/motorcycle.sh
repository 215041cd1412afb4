#!/bin/sh
# Stereo matching bar on the Middlebury 2014 Motorcycle pair (quarter resolution, as
# shipped by scikit-image; Scharstein et al., GCPR 2014): share of tie points within
# 1 px of the ground-truth disparity, with our extractor, and the OpenCV peer.
# usage: bench/match/motorcycle.sh [DATA_DIR]   (default: ../shared/data/stereo from the repo root)
set -e
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
DATA=${1:-$ROOT/../shared/data/stereo}
if [ ! -f "$DATA/motorcycle_disp.pfm" ]; then
    echo "motorcycle data missing at $DATA (pass the directory as the first argument)" >&2
    exit 2
fi
cd "$ROOT"
cargo build -q --release -p phototraverse-host
OUT=$(mktemp -d)
for refine in "" "--no-refine"; do
    echo "== phototraverse match --rectified --max-disparity 80 $refine"
    ./target/release/phototraverse match "$DATA/motorcycle_left.png" "$DATA/motorcycle_right.png" \
        --rectified --max-disparity 80 $refine --out "$OUT/m.txt"
    python3 bench/match/motorcycle_eval.py "$OUT/m.txt" --data "$DATA"
done
echo "== peer"
python3 bench/match/motorcycle_eval.py "$OUT/m.txt" --data "$DATA" --peer | tail -1
rm -rf "$OUT"
