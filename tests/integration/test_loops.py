"""One public constructor for every scene (issue 23): ``jellysim.Simulation(scene)`` builds the loop
the registry names for any preset and every combination the schema accepts, steps it frame by
frame with observers, declares its datasets up front, and computes what ``jellysim.run`` stores
(the reference runs of tests/regression, bit for bit). Sweeps run any scene with tentacles; a
checkpoint that does not hold the scene's state is refused with a sentence."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scenes
from pinning import NOT_PINNED, PINNED
from regression.cases import CASES, preset_of
from regression.compare import REFERENCE_FOLDER

import jellysim
from jellysim import fields
from jellysim.errors import InputError
from jellysim.simulation import LOOPS, FrameLoop, loop_name
from jellysim.studies import sweep

EXPECTED_LOOP = {
    "brown-jelly": "tentacles",
    "forced-tentacles": "tentacles",
    "purple-jelly": "tentacles",
    "lions-mane": "tentacles",
    "dam-break-2d": "fluid",
    "hydrostatic-2d": "fluid",
    "hydrostatic-3d": "fluid",
    "tank-3d": "fluid",
    "spheric-test2": "fluid",
    "moon-jelly": "soft-bell",
    "moon-jelly-weightless": "soft-bell",
    "moon-jelly-real-size": "soft-bell",
    "moon-jelly-fine": "soft-bell",
}
FRAMES = 2


def test_every_preset_has_a_loop_and_a_reference_case() -> None:
    assert set(EXPECTED_LOOP) == set(jellysim.preset_names())
    assert {preset_of(source) for source, _ in CASES.values()} == set(EXPECTED_LOOP)
    assert set(LOOPS) == {"tentacles", "fluid", "soft-bell"}


@pytest.mark.skipif(not PINNED, reason=NOT_PINNED)
@pytest.mark.parametrize("name", list(CASES))
def test_simulation_steps_any_scene_like_a_run(name: str) -> None:
    source, overrides = CASES[name]
    preset = preset_of(source)
    scene = jellysim.load_scene(source, overrides)
    loop = jellysim.Simulation(scene)
    assert isinstance(loop, jellysim.Simulation)
    assert isinstance(loop, LOOPS[EXPECTED_LOOP[preset]])
    assert loop_name(scene) == EXPECTED_LOOP[preset] == loop.loop
    contract: FrameLoop = loop  # the written contract (checked by mypy where annotated)
    assert contract.describe()

    seen: list[int] = []
    loop.observers.append(lambda simulation: seen.append(simulation.frame))
    declared = {spec.path: spec for spec in loop.datasets()}
    # A linked dataset is read back (and stored in the reference) under one of its names.
    stored_as = {path: path for path in declared} | {t: p for p, t in loop.links().items()}
    with np.load(REFERENCE_FOLDER / f"{name}.npz") as stored:
        for frame in range(FRAMES + 1):
            values = loop.frame_values()
            assert set(values) == set(declared)  # the datasets declared up front, no more
            for path, spec in declared.items():
                value = np.asarray(values[path]).astype(spec.dtype)
                assert value.shape == spec.frame_shape, path
                expected = stored[f"data:{stored_as[path]}"][frame]
                assert value.tobytes() == expected.tobytes(), (path, frame)
            if frame < FRAMES:
                loop.step_frame()
    assert seen == list(range(1, FRAMES + 1))
    assert loop.time == pytest.approx(FRAMES / scene.fps)
    for array in loop.checkpoint_state().values():
        assert isinstance(array, np.ndarray)


@pytest.mark.parametrize(
    ("preset", "overrides"),
    [
        ("forced-tentacles", {"duration": 0.2, "tentacles.count": 2}),
        ("moon-jelly", {**scenes.SMALL_MOON, "duration": 0.2, "fps": 10.0, "tentacles.count": 2}),
    ],
    ids=["tentacles", "soft-bell"],
)
def test_sweeps_run_scenes_with_tentacles(preset: str, overrides: dict[str, object]) -> None:
    traces = sweep(preset, "tentacles.youngs_modulus", [1e4, 1e6], overrides, tentacle=1)
    assert [trace.value for trace in traces] == [1e4, 1e6]
    scene = jellysim.load_scene(preset, {**overrides, "tentacles.youngs_modulus": 1e6})
    loop = jellysim.Simulation(scene)
    roots = [loop.frame_values()[fields.TENTACLE_POSITION.path][1, 0, 0]]
    for _ in range(scene.frame_count - 1):
        loop.step_frame()
        roots.append(loop.frame_values()[fields.TENTACLE_POSITION.path][1, 0, 0])
    assert traces[1].time.shape == (scene.frame_count,)
    np.testing.assert_array_equal(traces[1].root_x, roots)
    assert np.all(np.isfinite(traces[0].tip_x))


def test_a_sweep_of_a_fluid_only_scene_says_it_has_no_tentacles() -> None:
    with pytest.raises(InputError, match="has no tentacles"):
        sweep("dam-break-2d", "fluid.courant", [0.1], {"fluid.spacing": 0.01})


class _Stop(Exception):
    pass


def _stopped_run(folder: Path) -> jellysim.Scene:
    """A run of 7 frames stopped at frame 5 (frames 0-4 written), its checkpoint of frame 4
    left behind."""
    scene = jellysim.load_scene(
        "forced-tentacles",
        {"duration": 0.2, "tentacles.count": 2, "solver.checkpoint_every": 2},
    )

    def stop(simulation: jellysim.Simulation) -> None:
        if simulation.frame == 5:
            raise _Stop

    with pytest.raises(_Stop):
        jellysim.run(scene, folder, observers=[stop])
    return scene


def test_a_checkpoint_without_the_scenes_state_is_refused(tmp_path: Path) -> None:
    scene = _stopped_run(tmp_path)
    checkpoint = tmp_path / "checkpoint.npz"
    with np.load(checkpoint) as data:
        kept = {k: data[k] for k in data.files if k != "velocities"}
    np.savez(checkpoint, **kept)
    with pytest.raises(InputError, match="'velocities' is missing.*--force"):
        jellysim.run(scene, tmp_path, resume=True)
    kept["velocities"] = np.zeros((3, 3))
    np.savez(checkpoint, **kept)
    with pytest.raises(InputError, match=r"'velocities' has shape \(3, 3\)"):
        jellysim.run(scene, tmp_path, resume=True)


def _truncate(data: bytes) -> bytes:
    return data[: len(data) // 2]


def _flip_a_bit(data: bytes) -> bytes:
    middle = len(data) // 2
    return data[:middle] + bytes([data[middle] ^ 0x10]) + data[middle + 1 :]


@pytest.mark.parametrize(
    "damage",
    [_truncate, lambda data: b"", _flip_a_bit, lambda data: b"not a zip file at all"],
    ids=["truncated", "empty", "bit-flipped", "not-a-checkpoint"],
)
def test_a_damaged_checkpoint_is_refused_with_a_sentence(tmp_path: Path, damage: object) -> None:
    """Issue 24: the sentence names the checkpoint and --force; nothing is resumed."""
    scene = _stopped_run(tmp_path)
    checkpoint = tmp_path / "checkpoint.npz"
    checkpoint.write_bytes(damage(checkpoint.read_bytes()))  # type: ignore[operator]
    before = (tmp_path / "result.h5").read_bytes()
    with pytest.raises(InputError, match=r"checkpoint\.npz is damaged .*--force"):
        jellysim.run(scene, tmp_path, resume=True)
    assert (tmp_path / "result.h5").read_bytes() == before


@pytest.mark.parametrize("frame", [5, 6, 100, -1])
def test_a_checkpoint_beyond_the_written_frames_is_refused(tmp_path: Path, frame: int) -> None:
    """A checkpoint must be of a frame the result holds, before the last: a resume never reports
    success for an incomplete result (issue 24)."""
    scene = _stopped_run(tmp_path)
    checkpoint = tmp_path / "checkpoint.npz"
    with np.load(checkpoint) as data:
        assert int(data["frame"]) == 4
        kept = {k: data[k] for k in data.files}
    kept["frame"] = np.int64(frame)
    np.savez(checkpoint, **kept)
    with pytest.raises(InputError, match=r"is of frame .* holds frames 0-4 of 7.*--force"):
        jellysim.run(scene, tmp_path, resume=True)
    assert checkpoint.exists()
