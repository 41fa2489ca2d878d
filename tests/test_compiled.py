"""Compiled models kept on disk (pickplace.robot.compiled): a model loaded from the cache is the
compiled model bit for bit, a changed input compiles again, a bad file is replaced."""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np
import pytest

from pickplace.cache import CACHE_ENV
from pickplace.robot import compiled
from pickplace.robot.compiled import compile_cached, model_key
from pickplace.robot.compose import clear_calibration_cache
from pickplace.sim.loader import clear_scene_cache, load_scene

_OBJ = """v 0 0 0
v 0.1 0 0
v 0 0.12 0
v 0 0 0.09
vt 0 0
vt 1 0
vt 0 1
f 1/1 3/3 2/2
f 1/1 2/2 4/1
f 1/1 4/1 3/3
f 2/2 3/3 4/1
"""


def _spec(folder: Path) -> mujoco.MjSpec:
    (folder / "part.obj").write_text(_OBJ)
    return mujoco.MjSpec.from_string(
        f"""<mujoco><compiler meshdir="{folder}"/>
        <asset><mesh name="part" file="part.obj" scale="1 2 1"/></asset>
        <worldbody><body name="b"><freejoint/><geom type="mesh" mesh="part"/>
        <geom type="box" size=".1 .2 .3" pos="0 0 .5"/></body></worldbody></mujoco>"""
    )


def assert_same_model(a: mujoco.MjModel, b: mujoco.MjModel) -> None:
    """Every array and option of two models equal, bit for bit (NaN equal to NaN)."""
    compared = 0
    for name in dir(a):
        if name.startswith("_"):
            continue
        value = getattr(a, name)
        if isinstance(value, np.ndarray):
            other = getattr(b, name)
            assert value.dtype == other.dtype and value.shape == other.shape, name
            assert value.tobytes() == other.tobytes(), name
            compared += 1
    for name in dir(a.opt):
        if not name.startswith("_") and isinstance(getattr(a.opt, name), (float, int)):
            assert getattr(a.opt, name) == getattr(b.opt, name), name
    assert compared > 100  # the model's arrays were found


class _Counting:
    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, spec: mujoco.MjSpec) -> mujoco.MjModel:
        self.calls += 1
        return spec.compile()


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv(CACHE_ENV, str(folder))
    return folder


def test_second_compile_loads_the_same_model(tmp_path: Path, cache: Path) -> None:
    compile_spec = _Counting()
    first = compile_cached(_spec(tmp_path), "test", compile_spec)
    second = compile_cached(_spec(tmp_path), "test", compile_spec)
    assert compile_spec.calls == 1
    assert len(list(cache.glob("model-*.mjb"))) == 1
    assert_same_model(second, first)
    assert_same_model(second, _spec(tmp_path).compile())
    assert first.nmesh == 1 and first.nmeshvert > 0


def test_a_changed_mesh_file_or_key_compiles_again(tmp_path: Path, cache: Path) -> None:
    compile_spec = _Counting()
    spec = _spec(tmp_path)
    before = compile_cached(spec, "test", compile_spec)
    key = model_key(spec, "test")
    mesh = tmp_path / "part.obj"
    mesh.write_text(_OBJ.replace("v 0.1 0 0", "v 0.2 0 0"))
    later = mesh.stat().st_mtime + 10  # MuJoCo's own decoded-mesh cache goes by the time
    os.utime(mesh, (later, later))
    assert model_key(spec, "test") != key
    after = compile_cached(spec, "test", compile_spec)
    assert compile_spec.calls == 2
    assert not np.array_equal(after.mesh_vert, before.mesh_vert)
    compile_cached(spec, "other", compile_spec)
    assert compile_spec.calls == 3


@pytest.mark.parametrize("damage", ["truncated", "garbage", "empty"])
def test_a_damaged_file_is_compiled_again_and_replaced(
    tmp_path: Path, cache: Path, damage: str, capfd: pytest.CaptureFixture[str]
) -> None:
    compile_spec = _Counting()
    good = compile_cached(_spec(tmp_path), "test", compile_spec)
    (path,) = cache.glob("model-*.mjb")
    content = path.read_bytes()
    broken = {"truncated": content[: len(content) // 2], "garbage": b"x" * 4096, "empty": b""}
    path.write_bytes(broken[damage])
    again = compile_cached(_spec(tmp_path), "test", compile_spec)
    assert compile_spec.calls == 2
    assert_same_model(again, good)
    assert path.read_bytes() == content
    assert capfd.readouterr().err == ""  # MuJoCo's loader warning is not printed


def test_no_key_or_an_unwritable_folder_keeps_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv(CACHE_ENV, str(blocker / "cache"))  # a folder inside a file
    compile_spec = _Counting()
    for key in (None, "test", "test"):
        model = compile_cached(_spec(tmp_path), key, compile_spec)
    assert compile_spec.calls == 3 and model.nmesh == 1


def test_the_least_recently_used_models_are_pruned(
    tmp_path: Path, cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    compile_spec = _Counting()
    spec = _spec(tmp_path)
    files = {}
    for age, key in ((1, "a"), (2, "b")):  # written long ago, "a" first
        compile_cached(spec, key, compile_spec)
        files[key] = cache / f"model-{model_key(spec, key)}.mjb"
        os.utime(files[key], (age, age))
    monkeypatch.setattr(compiled, "MAX_MODEL_BYTES", 2 * files["a"].stat().st_size)
    compile_cached(spec, "a", compile_spec)  # loaded: now the most recently used
    assert compile_spec.calls == 2
    compile_cached(spec, "c", compile_spec)  # a third does not fit: "b" goes
    assert compile_spec.calls == 3
    kept = set(cache.glob("model-*.mjb"))
    assert kept == {files["a"], cache / f"model-{model_key(spec, 'c')}.mjb"}


def test_a_missing_mesh_file_is_not_keyed(tmp_path: Path, cache: Path) -> None:
    spec = _spec(tmp_path)
    (tmp_path / "part.obj").unlink()
    assert model_key(spec, "test") is None
    with pytest.raises(ValueError, match=r"part\.obj"):
        compile_cached(spec, "test", mujoco.MjSpec.compile)


def test_a_scene_loaded_from_disk_equals_the_compiled_one(
    cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A published arm's meshes (Menagerie's iiwa 14 and 2F-85): the second load, in-process
    # caches cleared as in a new process, compiles nothing that has a mesh.
    robot = "menagerie-iiwa14-2f85"
    clear_scene_cache()
    clear_calibration_cache()
    compiled = load_scene(robot=robot)
    assert compiled.model.nmesh > 0
    clear_scene_cache()
    clear_calibration_cache()
    with_meshes = []
    compile_spec = mujoco.MjSpec.compile

    def counting(spec: mujoco.MjSpec) -> mujoco.MjModel:
        model = compile_spec(spec)
        if model.nmesh:
            with_meshes.append(model)
        return model

    monkeypatch.setattr(mujoco.MjSpec, "compile", counting)
    loaded = load_scene(robot=robot)
    assert with_meshes == []
    assert_same_model(loaded.model, compiled.model)
    assert_same_model(loaded.arm_model, compiled.arm_model)
    assert np.array_equal(loaded.robot.q_home, compiled.robot.q_home)
