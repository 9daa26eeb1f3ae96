#!/usr/bin/env bash
# The gallery of docs/gallery.md: for every jellyfish preset a final-quality still and a short
# draft clip, plus the paper's Figs. 12 (the room with the tank) and 13 (a school of purple
# jellyfish), each from one `jellysim render` command.
#   examples/gallery.sh [OUT] [PRESET ...]   (default OUT: out/gallery; default: every preset)
# The stills and clips are copied to docs/gallery/ (small files: 640x480 PNG, 320x240 MP4).
# Times on 2 cores: the kinematic-bell presets a minute or two each; the soft-bell (Case 2)
# presets run their first 0.5 s (half of the real-size bell's contraction; moon-jelly 0.8 s, to
# its first contraction's peak), a few minutes each: their full runs take 13 minutes and more.
set -euo pipefail
out=${1:-out/gallery}
shift || true
jellysim=${JELLYSIM:-.venv/bin/jellysim}
docs=docs/gallery
mkdir -p "$docs"

# preset: simulated seconds, the still's frame, the clip's frames (A:B)
declare -A duration=(
  [brown-jelly]=6 [purple-jelly]=6 [lions-mane]=10
  [moon-jelly]=0.8 [moon-jelly-weightless]=0.5 [moon-jelly-real-size]=0.5
)
declare -A still=(
  [brown-jelly]=150 [purple-jelly]=150 [lions-mane]=270
  [moon-jelly]=16 [moon-jelly-weightless]=10 [moon-jelly-real-size]=10
)
declare -A clip=(
  [brown-jelly]=90:181 [purple-jelly]=90:181 [lions-mane]=210:301
  [moon-jelly]=0:17 [moon-jelly-weightless]=0:11 [moon-jelly-real-size]=0:11
)
presets=("$@")
if [ ${#presets[@]} -eq 0 ]; then
  presets=(brown-jelly purple-jelly lions-mane moon-jelly moon-jelly-weightless moon-jelly-real-size)
fi

for p in "${presets[@]}"; do
  "$jellysim" run "$p" --out "$out/$p" --force --quiet --set "duration=${duration[$p]}"
  f=${still[$p]}
  "$jellysim" render "$out/$p" --out "$out/$p/still" --quality final --frames "$f:$((f + 1))" \
    --no-video --force --quiet
  cp "$out/$p/still/frames/frame_$(printf %05d "$f").png" "$docs/$p.png"
  "$jellysim" render "$out/$p" --out "$out/$p/clip" --quality draft --size 320x240 \
    --frames "${clip[$p]}" --force --quiet
  cp "$out/$p/clip/movie.mp4" "$docs/$p.mp4"
done

# Fig. 12: the room with the jellyfish in a water tank, three lights, shadows on the wall.
if [ -d "$out/brown-jelly" ]; then
  "$jellysim" render "$out/brown-jelly" --out "$out/fig12" --room --quality final \
    --frames 150:151 --no-video --force --quiet
  cp "$out/fig12/frames/frame_00150.png" "$docs/fig12-room.png"
fi
# Fig. 13: a school of purple jellyfish, their long oral arms animated as the tentacles are.
if [ -d "$out/purple-jelly" ]; then
  "$jellysim" render "$out/purple-jelly" --out "$out/fig13" --school 6 --quality final \
    --frames 150:151 --no-video --force --quiet
  cp "$out/fig13/frames/frame_00150.png" "$docs/fig13-school.png"
fi
ls -la "$docs"
