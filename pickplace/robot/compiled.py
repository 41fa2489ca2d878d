"""Compiled MuJoCo models kept on disk, so that a second process loads instead of compiling.

Compiling a spec that names a published arm's meshes decodes the mesh files — 30 MB of OBJ
text for Menagerie's UR5e, most of a second — and MuJoCo keeps decoded meshes for the rest of
the process only, so every sweep worker paid it again. :func:`compile_cached` saves each model
it compiles as MJB (``mj_saveModel``, MuJoCo's own dump of the model's arrays) in the user's
cache folder (:func:`pickplace.cache.cache_dir`) as ``model-<key>.mjb``, and the next process
that compiles the same spec loads it (``MjModel.from_binary_path``): the model it gets equals
the compiled one bit for bit. The spec itself is left as it was (it is not compiled), so
whatever copies or edits it afterwards works as before.

The key digests what the spec was built from, given by the caller (the sanitised part
document, the world file, the description, the calibration: MuJoCo has no way to serialise a
spec without compiling it), the content of every asset file the spec names, the source of
every module of the package (code edits a spec before it is compiled) and the MuJoCo version.
A file is written to a temporary name and renamed, so a concurrent sweep worker reads a whole
file or none; one that does not load (truncated, corrupt, written by another MuJoCo) is
compiled again and replaced; a folder that cannot be written is skipped — the cache only saves
time. Each file is about the size of the model in memory (43 MB for the UR5e + 2F-85 scene,
mostly the meshes' bounding-volume trees; 125–200 MB for each Menagerie robot's models), so the
model files together are kept under :data:`MAX_MODEL_BYTES`: the least recently used go first.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import mujoco

from pickplace.cache import cache_dir, file_digest, source_digest
from pickplace.robot.mjcf import collected_warnings

_PACKAGE = Path(__file__).resolve().parent.parent

MAX_MODEL_BYTES = 1 << 30
"""Most disk the model files take together [bytes] (1 GiB: five to eight published robots'
scenes); writing one more deletes the least recently used (loading one marks it used)."""


@functools.cache
def package_digest() -> str:
    """SHA-256 of the source of every module of the package (read once per process)."""
    return source_digest(sorted(p.relative_to(_PACKAGE).as_posix() for p in _PACKAGE.rglob("*.py")))


def _asset_files(spec: mujoco.MjSpec) -> list[Path]:
    """Every file the spec's assets name, resolved as MuJoCo resolves them."""
    base = Path(spec.modelfiledir) if spec.modelfiledir else Path.cwd()
    compiler = spec.compiler
    mesh_dir = base / (compiler.meshdir or "")
    tex_dir = base / (compiler.texturedir or "")
    names: list[tuple[Path, str]] = []
    for collection in (spec.meshes, spec.hfields, spec.skins):
        names += [(mesh_dir, e.file) for e in collection if e.file]
    for texture in spec.textures:
        names += [(tex_dir, f) for f in (texture.file, *texture.cubefiles) if f]
    return [Path(name) if Path(name).is_absolute() else folder / name for folder, name in names]


def spec_files_digest(spec: mujoco.MjSpec) -> str | None:
    """SHA-256 of the content of every asset file ``spec`` names and of its in-memory assets,
    or None if a file cannot be read (the compile reports it)."""
    digest = hashlib.sha256()
    for path in _asset_files(spec):
        content = file_digest(path)
        if content is None:
            return None
        digest.update(f"{path}\n{content}\n".encode())
    for name in sorted(spec.assets):
        digest.update(name.encode())
        digest.update(hashlib.sha256(spec.assets[name]).digest())
    return digest.hexdigest()


def model_key(spec: mujoco.MjSpec, built_from: str) -> str | None:
    """The cache key of compiling ``spec``, built from what ``built_from`` digests; None if an
    asset file cannot be read."""
    files = spec_files_digest(spec)
    if files is None:
        return None
    parts = (mujoco.__version__, package_digest(), files, built_from)
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def _load(path: Path) -> mujoco.MjModel | None:
    if not path.is_file():
        return None
    with collected_warnings():  # a file that does not load is compiled again, silently
        try:
            model = mujoco.MjModel.from_binary_path(str(path))
        except ValueError:  # also if a concurrent prune deleted it meanwhile
            return None
    with contextlib.suppress(OSError):
        os.utime(path)  # recently used: pruned last
    return model


def _prune(folder: Path, keep: Path) -> None:
    """Delete the least recently used model files until they take at most
    :data:`MAX_MODEL_BYTES` (``keep``, just written, stays)."""
    files = []
    for f in folder.glob("model-*.mjb"):
        with contextlib.suppress(OSError):  # deleted by a concurrent prune
            st = f.stat()
            files.append((st.st_mtime_ns, st.st_size, f))
    total = sum(size for _, size, _ in files)
    for _, size, f in sorted(files):
        if total <= MAX_MODEL_BYTES:
            break
        if f != keep:
            f.unlink(missing_ok=True)
            total -= size


def _store(path: Path, model: mujoco.MjModel) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        os.close(fd)
        try:
            mujoco.mj_saveModel(model, tmp, None)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        _prune(path.parent, path)
    except (OSError, ValueError):
        return


def compile_cached(
    spec: mujoco.MjSpec,
    built_from: str | None,
    compile_spec: Callable[[mujoco.MjSpec], mujoco.MjModel],
) -> mujoco.MjModel:
    """``compile_spec(spec)``, or the model a process compiled before from the same spec.

    Args:
        spec: The spec to compile (not changed, and not compiled if the model is on disk).
        built_from: A digest of everything ``spec`` was built from besides its asset files and
            the package's code (see the module docstring); None: compile, keep nothing.
        compile_spec: Compiles ``spec`` (raising what a failed compile should raise).
    """
    key = None if built_from is None else model_key(spec, built_from)
    if key is None:
        return compile_spec(spec)
    path = cache_dir() / f"model-{key}.mjb"
    model = _load(path)
    if model is None:
        model = compile_spec(spec)
        _store(path, model)
    return model
