"""Reading a result in a script: open it, take the arrays with their units, hand them to xarray
and pandas, and answer a question (how far each tentacle's tip strays from below its root).

    .venv/bin/python examples/read_results.py [RESULT_DIR]

Without a folder it first runs a short brown-jelly into out/read_results.
"""

from __future__ import annotations

import sys
from pathlib import Path

import xarray

import jellysim


def main() -> None:
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("out/read_results")
    if not (folder / "result.h5").exists():
        jellysim.run(jellysim.load_scene("brown-jelly", {"duration": 1.0}), folder).close()
    with jellysim.open_result(folder) as result:
        print(f"{result.scene.name}: {result.frames} frames, groups {result.tentacle_groups}")
        ds = result.to_xarray()
    # The tips' horizontal distance from the point below their root, per frame and tentacle (m).
    position = ds["tentacles_position"]
    # Each tentacle's own last particle: a group's shorter chains are NaN-padded to P.
    last = xarray.DataArray(ds["tentacles_particles"].values - 1, dims="tentacle")
    tip = position.isel(particle=last)
    root = position.isel(particle=0)
    stray = ((tip - root).sel(xyz=["x", "y"]) ** 2).sum("xyz") ** 0.5
    stray.attrs["units"] = "m"
    table = stray.to_dataframe(name="tip_stray_m").reset_index()  # pandas: time, tentacle, value
    summary = table.groupby("tentacle")["tip_stray_m"].agg(["mean", "max"])
    print(summary.to_string())


if __name__ == "__main__":
    main()
