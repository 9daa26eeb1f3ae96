#!/usr/bin/env bash
# The paper's Figs. 5, 7 and 8 (Hirato & Kawaguchi, §4.1.2 and §5 Case 1): one tentacle of
# the forced-tentacles preset, its root forced radially at 1 Hz; root (red) and tip x against time.
#   examples/paper_figures.sh [OUT]    (default OUT: out/paper-figures)
set -euo pipefail
out=${1:-out/paper-figures}
jellysim=${JELLYSIM:-.venv/bin/jellysim}
common=(--set tentacles.count=1 --set flow.noise=0)

# Fig. 5: gelatine, rubber and Japanese cypress rods in a 0.3 m/s flow.
"$jellysim" sweep forced-tentacles "${common[@]}" --key tentacles.youngs_modulus \
  --values 2.4e5,5e6,9e9 --out "$out/fig5" --title "Fig. 5: rods of gelatine, rubber and cypress, v = 0.3 m/s"
# Fig. 7: Young's modulus from 0.1 kPa to 9 GPa, v = 0.3 m/s.
"$jellysim" sweep forced-tentacles "${common[@]}" --key tentacles.youngs_modulus \
  --values 100,1e4,2.4e5,5e6,9e9 --out "$out/fig7" --title "Fig. 7: wave propagation as E changes, v = 0.3 m/s"
# Fig. 8: flow speed from 0 to 1 m/s, E = 0.1 kPa.
"$jellysim" sweep forced-tentacles "${common[@]}" --key flow.speed \
  --values 0,0.3,0.6,1.0 --out "$out/fig8" --title "Fig. 8: wave propagation as the flow changes, E = 0.1 kPa"
