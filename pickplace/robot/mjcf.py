"""Load an arm or gripper MJCF file as published elsewhere, repairing what can be repaired.

Published robot files are written to be loaded on their own, or by another project's code; put
into a composed scene they meet these pitfalls (``docs/physics-notes.md``):

* asset paths relative to the file (or to its ``<compiler meshdir/texturedir/assetdir>``), which
  an attached child resolves against the parent's folder: every asset path is made absolute;
* ``<include>`` files: inlined, so the file is one document;
* no ``<compiler angle>``: MuJoCo then reads degrees, and ``attach`` keeps the child's compiler,
  so a finger range in radians silently shrinks 57-fold. The description's ``angle`` says what
  such a file means; a file without either is an error;
* the same asset defined twice: identical definitions are merged, different ones are an error;
* attributes MuJoCo's schema rejects (e.g. ``group`` on ``<default>``): removed, since MuJoCo
  could never have read them;
* ``<option>`` and ``<keyframe>`` (options belong to the scene; key sizes change when parts are
  composed) and geoms, sites, lights and cameras on the file's worldbody (a floor is not part of
  a robot): removed.

Every repair is reported in :attr:`Part.repairs`. What cannot be repaired raises
:class:`~pickplace.errors.RobotError` naming the file and the element.

Reading is bounded whatever the file (all limits in the message that refuses a file): each
file at most :data:`MAX_MJCF_BYTES`, a file and its includes together at most
:data:`MAX_MJCF_ELEMENTS` elements (counted while parsing, so a huge file stops early),
includes nested at most :data:`MAX_INCLUDE_DEPTH` deep, and a file that includes itself
(directly or through others) is refused at once with the chain of files.
"""

from __future__ import annotations

import contextlib
import hashlib
import re
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from pickplace.cache import file_digest, read_json, write_json
from pickplace.errors import RobotError, SceneError, file_problem

if TYPE_CHECKING:
    import mujoco

_MESH_DIR_ASSETS = ("mesh", "hfield", "skin")
"""Asset tags whose files MuJoCo looks for in ``meshdir``."""

_TEXTURE_FILE_ATTRS = (
    "file",
    "fileright",
    "fileleft",
    "fileup",
    "filedown",
    "filefront",
    "fileback",
)

_WORLD_ONLY = ("geom", "site", "light", "camera")
"""Worldbody children that are not parts of a robot."""

_UNRECOGNIZED = re.compile(r"unrecognized attribute: '([^']+)'.*?Element '([^']+)'", re.S)
_OPENING = re.compile(r"Error opening file '([^']+)'")
_ELEMENT = re.compile(r"Element name '([^']+)'")
_MAX_REPAIRS = 50

MAX_MJCF_BYTES = 16 << 20
"""Largest arm or gripper file, and included file [bytes]: published robot files are around
10 kB; this leaves room for mesh data written inline."""
MAX_MJCF_ELEMENTS = 20_000
"""Most XML elements in a file with its includes: published arms and grippers have 50–200,
whole humanoids a few thousand."""
MAX_INCLUDE_DEPTH = 8
"""Deepest nesting of ``<include>`` files (published robots use one level, if any)."""


@dataclass
class _Reading:
    """What reading one part has taken so far: the files read, the elements parsed."""

    files: list[Path]
    elements: int = 0


@dataclass(frozen=True)
class Part:
    """An arm or gripper file, sanitised into one self-contained MJCF document.

    Attributes:
        path: The file as named by the description.
        field: The description field that names it (``[arm] mjcf``), for messages.
        xml: The sanitised document (absolute asset paths, explicit ``<compiler angle>``).
        repairs: What was changed, one line each.
        digest: SHA-256 of the file, its includes and its asset files, and the angle used.
    """

    path: Path
    field: str
    xml: str
    repairs: tuple[str, ...]
    digest: str

    def new_spec(self) -> mujoco.MjSpec:
        """A fresh spec of the sanitised document (specs are mutable; make one per use)."""
        import mujoco  # here, not at the top: digests need no MuJoCo (pickplace robots)

        return mujoco.MjSpec.from_string(self.xml)

    def error(self, problem: str) -> RobotError:
        """A :class:`RobotError` about this file."""
        return RobotError(f"{self.path}: {self.field}: {problem}")


def mjcf_file_problem(path: Path, valid: str) -> str | None:
    """None if ``path`` is a regular file of at most :data:`MAX_MJCF_BYTES`; else what is wrong
    and what would be valid, for a message (``valid`` names the kind of file wanted, e.g. "an
    MJCF world file")."""
    problem = file_problem(path)
    if problem is not None:
        return f"{problem}; valid: {valid}"
    size = path.stat().st_size
    if size > MAX_MJCF_BYTES:
        return f"is {size} bytes; valid: {valid} of at most {MAX_MJCF_BYTES} bytes"
    return None


def _read_xml(path: Path, source: Path, field: str, reading: _Reading) -> ET.Element:
    """Parse ``path`` (size, element count and root checked); its elements count in
    ``reading``."""
    problem = mjcf_file_problem(path, "an MJCF file")
    if problem is not None:
        raise RobotError(f"{source}: {field}: '{path}' {problem}")
    root: ET.Element | None = None
    try:
        for _, element in ET.iterparse(path, events=("start",)):
            if root is None:
                root = element
            reading.elements += 1
            if reading.elements > MAX_MJCF_ELEMENTS:
                raise RobotError(
                    f"{source}: {field}: '{path}' (with the files it includes) has more than "
                    f"{MAX_MJCF_ELEMENTS} XML elements; valid: at most {MAX_MJCF_ELEMENTS} (a "
                    "robot has a few hundred)"
                )
    except (OSError, ET.ParseError) as exc:
        detail = " ".join(str(exc).split())[:300]
        raise RobotError(
            f"{source}: {field}: '{path}' is not readable XML: {detail}; valid: an MJCF file"
        ) from exc
    if root is None or root.tag != "mujoco":
        tag = "none" if root is None else f"<{root.tag[:60]}>"
        raise RobotError(f"{source}: {field}: '{path}' has root element {tag}; valid: <mujoco>")
    return root


def _inline_includes(
    root: ET.Element,
    base: Path,
    source: Path,
    field: str,
    reading: _Reading,
    chain: tuple[Path, ...],
) -> None:
    """Replace every ``<include file>`` by the children of the included ``<mujoco>``, its own
    includes first (depth first, at most :data:`MAX_INCLUDE_DEPTH` deep).

    Paths are relative to the main file's folder, as MuJoCo resolves them. ``chain`` is the
    files being included, the main file first: one of them again is a cycle.
    """
    for parent in list(root.iter()):  # the elements of this file, not of what is inlined
        for include in [child for child in parent if child.tag == "include"]:
            name = include.get("file")
            if not name:
                raise RobotError(
                    f"{source}: {field}: <include> without a file attribute; valid: "
                    f'<include file="..."/>'
                )
            path = Path(name) if Path(name).is_absolute() else base / name
            resolved = path.resolve()
            if resolved in chain:
                cycle = " -> ".join(f"'{f.name}'" for f in (*chain, resolved))
                raise RobotError(
                    f'{source}: {field}: <include file="{name}"> includes itself ({cycle}); '
                    "valid: includes without cycles"
                )
            if len(chain) > MAX_INCLUDE_DEPTH:
                raise RobotError(
                    f'{source}: {field}: <include file="{name}"> is nested more than '
                    f"{MAX_INCLUDE_DEPTH} deep; valid: at most {MAX_INCLUDE_DEPTH} levels"
                )
            problem = file_problem(path)
            if problem is not None:
                what = "not found" if problem == "does not exist" else problem
                raise RobotError(
                    f"{source}: {field}: <include file=\"{name}\">: '{path}' {what}; valid: "
                    f"an MJCF file, its path relative to '{base}'"
                )
            reading.files.append(path)
            included = _read_xml(path, source, field, reading)
            _inline_includes(included, base, source, field, reading, (*chain, resolved))
            at = list(parent).index(include)
            parent.remove(include)
            for k, child in enumerate(list(included)):
                parent.insert(at + k, child)


def _asset_dirs(root: ET.Element, base: Path) -> tuple[Path, Path, bool]:
    """Mesh and texture folders of a document, and whether ``strippath`` is on."""
    meshdir = texturedir = assetdir = None
    strip = False
    for compiler in root.iter("compiler"):
        meshdir = compiler.get("meshdir", meshdir)
        texturedir = compiler.get("texturedir", texturedir)
        assetdir = compiler.get("assetdir", assetdir)
        strip = compiler.get("strippath", "false" if not strip else "true") == "true"
    mesh = meshdir if meshdir is not None else assetdir
    tex = texturedir if texturedir is not None else assetdir
    return (base / mesh if mesh else base), (base / tex if tex else base), strip


def _resolve_assets(
    root: ET.Element, base: Path, source: Path, field: str, files: list[Path]
) -> list[str]:
    repairs: list[str] = []
    resolved = 0
    mesh_dir, tex_dir, strip = _asset_dirs(root, base)
    for compiler in root.iter("compiler"):
        for attr in ("meshdir", "texturedir", "assetdir", "strippath"):
            compiler.attrib.pop(attr, None)
    for element in root.iter():
        attrs: tuple[str, ...]
        if element.tag == "model":
            attrs, folder = ("file",), base
        elif element.tag in _MESH_DIR_ASSETS:
            attrs, folder = ("file",), mesh_dir
        elif element.tag == "texture":
            attrs, folder = _TEXTURE_FILE_ATTRS, tex_dir
        else:
            continue
        for attr in attrs:
            name = element.get(attr)
            if not name:
                continue
            rel = Path(Path(name).name if strip else name)
            path = rel if rel.is_absolute() else (folder / rel).resolve()
            what = f"{element.tag} '{element.get('name', rel.stem)}'"
            problem = file_problem(path)
            if problem is not None:
                raise RobotError(
                    f"{source}: {field}: {what} does not load: file '{path}' {problem}; "
                    f"valid: a path relative to the MJCF file's folder (or its compiler's "
                    f"meshdir/texturedir/assetdir)"
                )
            files.append(path)
            if str(path) != name:
                element.set(attr, str(path))
                resolved += 1
    if resolved:
        repairs.append(f"{resolved} asset paths made absolute (against '{base}')")
    return repairs


def _merge_repeated_assets(root: ET.Element, source: Path, field: str) -> list[str]:
    repairs: list[str] = []
    for asset in root.iter("asset"):
        seen: dict[tuple[str, str], ET.Element] = {}
        for element in list(asset):
            name = element.get("name") or (
                Path(element.get("file", "")).stem if element.get("file") else None
            )
            if not name:
                continue
            key = (element.tag, name)
            if key not in seen:
                seen[key] = element
                continue
            if seen[key].attrib == element.attrib and len(element) == 0:
                asset.remove(element)
                repairs.append(f"{element.tag} '{name}' defined twice identically: merged")
            else:
                raise RobotError(
                    f"{source}: {field}: {element.tag} '{name}' is defined twice with different "
                    f"attributes; valid: one definition per name"
                )
    return repairs


def _set_angle(root: ET.Element, angle: str | None, source: Path, field: str) -> str:
    authored = [c.get("angle") for c in root.iter("compiler") if c.get("angle")]
    file_angle = authored[-1] if authored else None
    if file_angle is None and angle is None:
        raise RobotError(
            f"{source}: {field}: the file has no <compiler angle>, so its angles' units are "
            f'unknown; valid: add angle = "radian" or "degree" to this table'
        )
    if file_angle is not None and angle is not None and file_angle != angle:
        raise RobotError(
            f'{source}: {field.replace("mjcf", "angle")}: "{angle}" contradicts the file\'s '
            f'<compiler angle="{file_angle}">; valid: remove the field, or "{file_angle}"'
        )
    used = file_angle if file_angle is not None else str(angle)
    compilers = list(root.iter("compiler"))
    if not compilers:
        compiler = ET.Element("compiler")
        root.insert(0, compiler)
        compilers = [compiler]
    for compiler in compilers:
        compiler.set("angle", used)
    return used


def _strip_scene_parts(root: ET.Element) -> list[str]:
    repairs: list[str] = []
    for tag in ("option", "keyframe"):
        for element in list(root.findall(tag)):
            root.remove(element)
            repairs.append(f"<{tag}> removed (it belongs to the scene)")
    for world in root.findall("worldbody"):
        for element in list(world):
            if element.tag in _WORLD_ONLY:
                world.remove(element)
                label = element.get("name", "unnamed")
                repairs.append(f"worldbody {element.tag} '{label}' removed (not part of a robot)")
    return repairs


def _parse_with_repairs(
    root: ET.Element, source: Path, field: str
) -> tuple[str, mujoco.MjSpec, list[str]]:
    import mujoco

    repairs: list[str] = []
    for _ in range(_MAX_REPAIRS):
        xml = ET.tostring(root, encoding="unicode")
        try:
            return xml, mujoco.MjSpec.from_string(xml), repairs
        except ValueError as exc:
            message = str(exc)
            match = _UNRECOGNIZED.search(message)
            if match is None:
                detail = " ".join(re.sub(r",? ?line \d+", "", message).split())
                raise RobotError(
                    f"{source}: {field}: MuJoCo cannot load it: {detail}; valid: a file that "
                    f"MuJoCo loads on its own"
                ) from exc
            attr, tag = match.groups()
            removed = 0
            for element in root.iter(tag):
                if attr in element.attrib:
                    del element.attrib[attr]
                    removed += 1
            if removed == 0:
                raise RobotError(
                    f"{source}: {field}: MuJoCo rejects attribute '{attr}' on <{tag}>; valid: "
                    f"attributes of MuJoCo's schema"
                ) from exc
            repairs.append(f"attribute '{attr}' on <{tag}> removed ({removed}x): MuJoCo rejects it")
    raise RobotError(
        f"{source}: {field}: more than {_MAX_REPAIRS} rejected attributes; valid: an MJCF file "
        f"for MuJoCo {mujoco.__version__}"
    )


def _check_compiles(spec: mujoco.MjSpec, source: Path, field: str) -> None:
    try:
        spec.compile()
    except ValueError as exc:
        message = " ".join(re.sub(r",? ?line \d+", "", str(exc)).split())
        opening = _OPENING.search(message)
        element = _ELEMENT.search(message)
        for mesh in spec.meshes:
            named = element is not None and element.group(1) == mesh.name
            opened = opening is not None and Path(opening.group(1)).name == Path(mesh.file).name
            if named or opened:
                raise RobotError(
                    f"{source}: {field}: mesh '{mesh.name}' (file '{mesh.file}') does not load: "
                    f"{message}; valid: a mesh file MuJoCo reads (STL, OBJ or MSH)"
                ) from exc
        raise RobotError(
            f"{source}: {field}: MuJoCo cannot compile it: {message}; valid: a file that "
            f"compiles in MuJoCo on its own"
        ) from exc


def _sanitised_tree(
    path: Path, field: str, angle: str | None, src: Path
) -> tuple[ET.Element, list[Path], str, list[str]]:
    """The file read, its includes inlined, its angle set, scene parts stripped and asset paths
    made absolute: the tree, every file it depends on, the angle used and the repairs."""
    files = [path]
    reading = _Reading(files)
    root = _read_xml(path, src, field, reading)
    base = path.parent
    _inline_includes(root, base, src, field, reading, (path.resolve(),))
    used_angle = _set_angle(root, angle, src, field)
    repairs = _strip_scene_parts(root)
    repairs += _resolve_assets(root, base, src, field, files)
    return root, files, used_angle, repairs


def _digest(used_angle: str, files: list[Path]) -> str:
    digest = hashlib.sha256(used_angle.encode())
    for f in files:  # contents only: the same files elsewhere share a calibration
        content = file_digest(f)
        if content is None:  # checked readable while sanitising; gone since
            raise RobotError(f"'{f}' cannot be read; valid: a readable file")
        digest.update(content.encode())
    return digest.hexdigest()


_Stamp = tuple[str, int, int]  # path, mtime [ns], size [bytes]

_PART_DIGESTS: dict[tuple[Path, str, str | None, Path], tuple[tuple[_Stamp, ...], str]] = {}


def file_stamps(files: list[Path]) -> tuple[_Stamp, ...] | None:
    """Each file's path, modification time [ns] and size [bytes], or None if one cannot be
    read: what a per-process cache of a file's parse is keyed by, so that a file asked for
    again is stat'ed, not read again (and read again once it changed)."""
    out = []
    for f in files:
        try:
            st = f.stat()
        except OSError:
            return None
        out.append((str(f), st.st_mtime_ns, st.st_size))
    return tuple(out)


def part_digest(path: Path, field: str, angle: str | None, source: Path | None = None) -> str:
    """:attr:`Part.digest` of a file without loading it into MuJoCo (XML parsing only).

    Remembered per process with the modification time and size of every file it read (the
    file, its includes and assets): asked again while none of them changed, the files are
    not read again.

    Raises:
        RobotError: As :func:`load_part`, for a missing file, include or asset.
    """
    path = path.resolve()
    key = (path, field, angle, source or path)
    known = _PART_DIGESTS.get(key)
    if known is not None and file_stamps([Path(f) for f, _, _ in known[0]]) == known[0]:
        return known[1]
    _, files, used_angle, _ = _sanitised_tree(path, field, angle, source or path)
    stamps = file_stamps(files)
    digest = _digest(used_angle, files)
    if stamps is not None:
        _PART_DIGESTS[key] = (stamps, digest)
    return digest


def load_part(path: Path, field: str, angle: str | None, source: Path | None = None) -> Part:
    """Read an arm or gripper file and sanitise it into a self-contained document.

    Args:
        path: The MJCF file.
        field: The description field naming it (``[arm] mjcf``), for messages.
        angle: Units of its angles if the file has no ``<compiler angle>`` (or None).
        source: The description file, named in messages (default: ``path`` itself).

    Raises:
        RobotError: The file is missing, not MuJoCo XML, has no known angle units, an
            asset does not exist or does not load, or MuJoCo rejects it for a reason that is
            not repairable.
    """
    path = path.resolve()
    src = source or path
    root, files, used_angle, repairs = _sanitised_tree(path, field, angle, src)
    repairs += _merge_repeated_assets(root, src, field)
    xml, spec, more = _parse_with_repairs(root, src, field)
    repairs += more
    digest = _digest(used_angle, files)
    _compiles_once(spec, xml, digest, src, field)
    return Part(path=path, field=field, xml=xml, repairs=tuple(repairs), digest=digest)


def _compiles_once(spec: mujoco.MjSpec, xml: str, digest: str, source: Path, field: str) -> None:
    """:func:`_check_compiles`, unless this very document (its sanitised XML, naming every
    asset by path, and ``digest``, the content of every file it reads) compiled before with
    this MuJoCo: remembered in the user's cache folder (:mod:`pickplace.cache`), since
    compiling a published arm's meshes on its own takes most of a second, in every process."""
    import mujoco

    key = hashlib.sha256(f"{mujoco.__version__}\n{digest}\n{xml}".encode()).hexdigest()
    name = f"compiles-{key}.json"
    if read_json(name) is True:
        return
    _check_compiles(spec, source, field)
    write_json(name, True)


def parse_world(path: Path) -> mujoco.MjSpec:
    """Parse a world file into a spec, turning every failure into a :class:`SceneError`.

    The one parser of world files: the composition, the loader and the run use it.
    """
    import mujoco

    path = path.resolve()  # MuJoCo misresolves nested <model file=...> for relative paths.
    problem = mjcf_file_problem(path, "an MJCF world file")
    if problem is not None:
        raise SceneError(f"scene file '{path}' {problem}")
    try:
        with collected_warnings() as warned:
            spec = mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:  # MuJoCo reports parse errors as ValueError.
        detail = " ".join(str(exc).split())
        raise SceneError(f"scene file '{path}' is not valid MJCF: {detail}") from exc
    if any("NaN" in w for w in warned):
        raise SceneError(
            f"scene file '{path}' contains a NaN (MuJoCo: {warned[0]}); valid: finite numbers"
        )
    for w in warned:  # anything else MuJoCo says while parsing: a Python warning
        warnings.warn(f"MuJoCo: {w}", stacklevel=2)
    return spec


@contextlib.contextmanager
def collected_warnings() -> Iterator[list[str]]:
    """Collect MuJoCo's C warnings in the block (instead of printing them and writing
    ``MUJOCO_LOG.TXT``); yields the list, filled as they come."""
    import mujoco  # here, not at the top (see Part.new_spec)

    collected: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda text: collected.append(" ".join(text.split())))
    try:
        yield collected
    finally:
        mujoco.set_mju_user_warning(previous)
