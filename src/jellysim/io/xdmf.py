"""The XDMF sidecar ``result.xdmf``: ParaView and VisIt open ``result.h5`` itself through it.

XDMF (version 2, what ParaView's "XDMF Reader", VTK's ``vtkXdmfReader`` and VisIt read) is an
XML description of meshes whose numbers stay in HDF5: each part of the result is a temporal
collection with one grid per frame, whose points and point arrays are hyperslabs (the frame's
rows) of the per-frame datasets of ``result.h5``, so nothing is copied. Parts, as the VTK
export names them (docs/exports.md):

- ``tentacles`` (``tentacles_NAME`` per group of a scene of several): one polyline per
  simulated tentacle through its own particles (no NaN padding), point array ``velocity``;
- ``rim``: the tentacle base points, ``velocity``;
- ``margin``: the bell margin as one closed polyline;
- ``bell``: the bell's surface triangles (``bell/surface_faces`` over ``bell/surface_vertices``);
- ``bell_particles``: a mass-spring bell's particles joined by its springs (line cells),
  ``velocity``, per spring ``muscle``;
- ``fluid``: the fluid and tank particles (vertices; (x, y) in 2-D), ``velocity``,
  ``pressure``, ``number_density``, ``alive``, ``kind``.

The writer (:class:`jellysim.io.result.ResultWriter`) removes the old sidecar before its new
file takes the name ``result.h5``, writes the sidecar once the file holds a frame (a document
of no frame crashes ``vtkXdmfReader``), and again as frames are flushed,
each time whole into a temporary file then renamed over the old one, so a sidecar on disk always
opens and lists frames the ``result.h5`` beside it holds.
``jellysim export DIR --format xdmf`` writes one for a result written before sidecars.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape

import h5py
import numpy as np

from jellysim import fields
from jellysim.config.schema import DEFAULT_GROUP

XDMF_FILE = "result.xdmf"

# XDMF's name and byte size of each element type stored (HDF5 converts on reading: a bool,
# stored as an HDF5 enum of int8, reads as an unsigned char).
_NUMBER_TYPES = {
    np.dtype(np.float64): ("Float", 8),
    np.dtype(np.float32): ("Float", 4),
    np.dtype(np.int64): ("Int", 8),
    np.dtype(np.int32): ("Int", 4),
    np.dtype(np.int8): ("Char", 1),
    np.dtype(np.bool_): ("UChar", 1),
}


@dataclass(frozen=True)
class _Array:
    """A per-frame point (or cell) array of a part: its name, dataset and XDMF attribute type."""

    name: str
    path: str
    kind: str  # "Scalar" or "Vector"


@dataclass(frozen=True)
class _Part:
    """One mesh of the result, as a temporal collection of grids.

    ``rows``: the (start, count) of each axis of a frame's positions that the part takes
    (tentacle groups: their tentacles and their own particles); ``topology``: the Topology
    element, the same in every frame; ``static``: arrays written once, as XDMF Attribute
    elements."""

    name: str
    position: str
    rows: tuple[tuple[int, int], ...]
    topology: str
    arrays: tuple[_Array, ...] = ()
    static: str = ""


def _attribute(value: str) -> str:
    """``value`` as the text of an XML attribute in double quotes."""
    return escape(value, {'"': "&quot;"})


def _number_type(dtype: np.dtype) -> str:
    name, size = _NUMBER_TYPES[np.dtype(dtype)]
    return f'NumberType="{name}" Precision="{size}"'


def _heavy(f: h5py.File, reference: str, path: str) -> str:
    """An XDMF DataItem naming a whole dataset of ``result.h5`` (``reference`` is its file name
    as seen from the sidecar)."""
    ds = f[path]
    shape = " ".join(str(n) for n in ds.shape)
    return (
        f'<DataItem Dimensions="{shape}" {_number_type(ds.dtype)} Format="HDF">'
        f"{escape(f'{reference}:/{path}')}</DataItem>"
    )


def _placeholder(path: str) -> str:
    """What stands for dataset ``path``'s DataItem in a cached grid (no XML text holds NUL)."""
    return f"\x00{path}\x00"


class _Slabs:
    """Hyperslab DataItems of the per-frame datasets of ``f``, each dataset looked up once."""

    def __init__(self, f: h5py.File, reference: str, placeholders: bool = False) -> None:
        """``placeholders``: name each dataset by :func:`_placeholder` instead of its DataItem,
        whose dimensions grow with the file's frames (:meth:`heavy` gives them when needed)."""
        self._f = f
        self._reference = reference
        self._placeholders = placeholders
        self._known: dict[str, tuple[tuple[int, ...], str]] = {}

    def heavy(self) -> dict[str, str]:
        """Each placeholder used so far and the DataItem it stands for, as the file is now."""
        return {_placeholder(path): _heavy(self._f, self._reference, path) for path in self._known}

    def __call__(self, path: str, frame: int, rows: Sequence[tuple[int, int]]) -> str:
        """Frame ``frame`` of dataset ``path``: the ``rows`` (start, count) of its leading
        frame axes and every row of the others.

        The DataItem's first child is a comment naming the frame: ``vtkXdmfReader`` keys its
        cache of a grid's points by the text of the geometry's first DataItem's first child,
        and without a text of its own per frame it logs an error at each frame (or, given
        equal texts, would show one frame's points at every frame)."""
        if path not in self._known:
            heavy = (
                _placeholder(path) if self._placeholders else _heavy(self._f, self._reference, path)
            )
            self._known[path] = (self._f[path].shape[1:], heavy)
        frame_shape, heavy = self._known[path]
        starts = [frame] + [start for start, _ in rows] + [0] * (len(frame_shape) - len(rows))
        counts = [1] + [count for _, count in rows] + list(frame_shape[len(rows) :])
        rank = len(counts)
        selection = " ".join(str(n) for n in (*starts, *([1] * rank), *counts))
        size = int(np.prod(counts))
        # Points and vectors: (nodes, components); a per-node scalar: (nodes,).
        dims = f"{size // counts[-1]} {counts[-1]}" if len(frame_shape) > 1 else f"{size}"
        return (
            f'<DataItem ItemType="HyperSlab" Dimensions="{dims}" Type="HyperSlab">'
            f"<!-- frame {frame} -->\n"
            f'     <DataItem Dimensions="3 {rank}" Format="XML">{selection}</DataItem>\n'
            f"     {heavy}\n"
            "    </DataItem>"
        )


def _connectivity(name: str, rows: np.ndarray) -> str:
    """A named connectivity table, inline (the Domain's; grids refer to it by name)."""
    values = " ".join(str(int(v)) for v in rows.ravel())
    return (
        f'  <DataItem Name="{_attribute(name)}" Dimensions="{rows.shape[0]} {rows.shape[1]}" '
        f'NumberType="Int" Format="XML">{values}</DataItem>\n'
    )


def _referenced(name: str) -> str:
    path = escape(f'/Xdmf/Domain/DataItem[@Name="{name}"]')
    return f'<DataItem Reference="XML">{path}</DataItem>'


def _tentacle_parts(f: h5py.File) -> tuple[list[_Part], str]:
    """A polyline part per tentacle group, and the Domain's connectivity tables."""
    _, count, particles, _ = f[fields.TENTACLE_POSITION.path].shape
    names = f.attrs.get("tentacle_groups")
    groups = (
        [DEFAULT_GROUP]
        if names is None
        else [n.decode() if isinstance(n, bytes) else str(n) for n in np.atleast_1d(names)]
    )
    group = (
        f[fields.TENTACLE_GROUP.path][()]
        if fields.TENTACLE_GROUP.path in f
        else np.zeros(count, dtype=np.int32)
    )
    own = (
        f[fields.TENTACLE_PARTICLES.path][()]
        if fields.TENTACLE_PARTICLES.path in f
        else np.full(count, particles, dtype=np.int32)
    )
    parts, tables = [], ""
    for number, name in enumerate(groups):
        rows = np.flatnonzero(group == number)  # a group's tentacles are contiguous along T
        if rows.size == 0:
            continue
        first, tentacles, nodes = int(rows[0]), int(rows.size), int(own[rows].max())
        part = "tentacles" if len(groups) == 1 else f"tentacles_{name}"
        table = f"{part}_connectivity"
        tables += _connectivity(table, np.arange(tentacles * nodes).reshape(tentacles, nodes))
        topology = (
            f'<Topology TopologyType="Polyline" NodesPerElement="{nodes}" '
            f'NumberOfElements="{tentacles}">{_referenced(table)}</Topology>'
        )
        velocity = _Array("velocity", fields.TENTACLE_VELOCITY.path, "Vector")
        parts.append(
            _Part(
                part,
                fields.TENTACLE_POSITION.path,
                ((first, tentacles), (0, nodes)),
                topology,
                (velocity,) if fields.TENTACLE_VELOCITY.path in f else (),
            )
        )
    return parts, tables


def _parts(f: h5py.File, reference: str) -> tuple[list[_Part], str]:
    """The parts ``f`` holds, and the connectivity tables they refer to."""
    parts: list[_Part] = []
    tables = ""
    if fields.TENTACLE_POSITION.path in f:
        parts, tables = _tentacle_parts(f)
    if fields.BELL_RIM.path in f:
        count = f[fields.BELL_RIM.path].shape[1]
        parts.append(
            _Part(
                "rim",
                fields.BELL_RIM.path,
                (),
                f'<Topology TopologyType="Polyvertex" NumberOfElements="{count}" '
                'NodesPerElement="1"/>',
                (_Array("velocity", fields.BELL_RIM_VELOCITY.path, "Vector"),)
                if fields.BELL_RIM_VELOCITY.path in f
                else (),
            )
        )
    if fields.BELL_MARGIN.path in f:
        points = f[fields.BELL_MARGIN.path].shape[1]
        tables += _connectivity("margin_connectivity", np.append(np.arange(points), 0)[None])
        parts.append(
            _Part(
                "margin",
                fields.BELL_MARGIN.path,
                (),
                f'<Topology TopologyType="Polyline" NodesPerElement="{points + 1}" '
                f'NumberOfElements="1">{_referenced("margin_connectivity")}</Topology>',
            )
        )
    faces = fields.BELL_SURFACE_FACES.path
    if fields.BELL_SURFACE_VERTICES.path in f and faces in f:
        parts.append(
            _Part(
                "bell",
                fields.BELL_SURFACE_VERTICES.path,
                (),
                f'<Topology TopologyType="Triangle" NumberOfElements="{f[faces].shape[0]}">'
                f"{_heavy(f, reference, faces)}</Topology>",
            )
        )
    springs = fields.BELL_SPRINGS.path
    if fields.BELL_POSITION.path in f and springs in f:
        muscle = fields.BELL_MUSCLE.path
        parts.append(
            _Part(
                "bell_particles",
                fields.BELL_POSITION.path,
                (),
                f'<Topology TopologyType="Polyline" NodesPerElement="2" '
                f'NumberOfElements="{f[springs].shape[0]}">{_heavy(f, reference, springs)}'
                "</Topology>",
                (_Array("velocity", fields.BELL_VELOCITY.path, "Vector"),)
                if fields.BELL_VELOCITY.path in f
                else (),
                f'<Attribute Name="muscle" AttributeType="Scalar" Center="Cell">'
                f"{_heavy(f, reference, muscle)}</Attribute>"
                if muscle in f
                else "",
            )
        )
    if fields.FLUID_POSITION.path in f:
        count = f[fields.FLUID_POSITION.path].shape[1]
        kind = fields.FLUID_KIND.path
        arrays = (
            _Array("velocity", fields.FLUID_VELOCITY.path, "Vector"),
            _Array("pressure", fields.FLUID_PRESSURE.path, "Scalar"),
            _Array("number_density", fields.FLUID_NUMBER_DENSITY.path, "Scalar"),
            _Array("alive", fields.FLUID_ALIVE.path, "Scalar"),
        )
        parts.append(
            _Part(
                "fluid",
                fields.FLUID_POSITION.path,
                (),
                f'<Topology TopologyType="Polyvertex" NumberOfElements="{count}" '
                'NodesPerElement="1"/>',
                tuple(a for a in arrays if a.path in f),
                f'<Attribute Name="kind" AttributeType="Scalar" Center="Node">'
                f"{_heavy(f, reference, kind)}</Attribute>"
                if kind in f
                else "",
            )
        )
    return parts, tables


def _grid(slab: _Slabs, part: _Part, dimensions: int, frame: int, time: float) -> str:
    lines = [
        f'   <Grid Name="{_attribute(part.name)}" GridType="Uniform">',
        f'    <Time Value="{time!r}"/>',
        f"    {part.topology}",
        f'    <Geometry GeometryType="{"XYZ" if dimensions == 3 else "XY"}">',
        f"    {slab(part.position, frame, part.rows)}",
        "    </Geometry>",
    ]
    for array in part.arrays:
        lines += [
            f'    <Attribute Name="{_attribute(array.name)}" AttributeType="{array.kind}" '
            'Center="Node">',
            f"    {slab(array.path, frame, part.rows)}",
            "    </Attribute>",
        ]
    if part.static:
        lines.append(f"    {part.static}")
    lines.append("   </Grid>")
    return "\n".join(lines)


class SidecarCache:
    """What a writer's repeated sidecars share: the parts and connectivity tables of its file
    (fixed once it is created) and each frame's grids (fixed once the frame is written), so that
    rewriting the sidecar of a growing result formats only the frames added since."""

    def __init__(self) -> None:
        self.reference: str | None = None
        self.parts: list[_Part] = []
        self.tables = ""
        self.slab: _Slabs | None = None
        self.grids: dict[tuple[int, int], str] = {}  # (part, frame): its grid's text


def xdmf_text(
    f: h5py.File, reference: str, frames: Sequence[int], cache: SidecarCache | None = None
) -> str:
    """The XDMF document describing ``frames`` of the result open as ``f``, whose file the
    document names ``reference`` (relative to the document's folder). ``cache``, kept by a
    writer whose file only grows by frames, spares formatting again what an earlier call of the
    same file and reference formatted; the text is the same with or without it."""
    times = f[fields.TIME.path][()]
    if cache is None or cache.reference != reference or cache.slab is None:
        parts, tables = _parts(f, reference)
        slab = _Slabs(f, reference, placeholders=cache is not None)
        if cache is not None:
            cache.reference, cache.parts, cache.tables, cache.slab = reference, parts, tables, slab
            cache.grids.clear()
    else:
        parts, tables, slab = cache.parts, cache.tables, cache.slab
    grids_of = {} if cache is None else cache.grids
    collections = []
    for number, part in enumerate(parts):
        dimensions = f[part.position].shape[-1]
        texts = []
        for k in frames:
            text = grids_of.get((number, k))
            if text is None:
                text = _grid(slab, part, dimensions, k, float(times[k]))
                if cache is not None:
                    grids_of[(number, k)] = text
            texts.append(text)
        grids = "\n".join(texts)
        collections.append(
            f'  <Grid Name="{_attribute(part.name)}" GridType="Collection" '
            'CollectionType="Temporal">\n'
            f"{grids}\n  </Grid>\n"
        )
    text = (
        '<?xml version="1.0" ?>\n'
        '<Xdmf Version="2.0">\n'
        " <Domain>\n"
        f"{tables}{''.join(collections)}"
        " </Domain>\n"
        "</Xdmf>\n"
    )
    if cache is not None:
        for placeholder, heavy in slab.heavy().items():
            text = text.replace(placeholder, heavy)
    return text


def result_reference(result: Path, folder: Path) -> str:
    """The name of the result at ``result`` in a sidecar in ``folder``: its relative path.
    Raises ValueError for a path holding ':', which XDMF 2's ``FILE:/DATASET`` form does not
    allow (``vtkXdmfReader`` reads ``../a:b/result.h5:/time`` as the file ``b/result.h5``)."""
    reference = os.path.relpath(result.resolve(), folder.resolve())
    if ":" in reference:
        raise ValueError(f"XDMF cannot name a file whose path has a ':' ('{reference}')")
    return reference


def write_xdmf(
    f: h5py.File,
    result: Path,
    path: Path,
    frames: Sequence[int],
    cache: SidecarCache | None = None,
    *,
    only_if_changed: bool = False,
) -> int:
    """Write to ``path`` the XDMF document of ``frames`` of ``f``, the result at ``result``
    (named in the document by its path relative to ``path``'s folder, :func:`result_reference`),
    whole or not at all: into a temporary file of this write's own, renamed over ``path``, so
    writers of the same sidecar (a run, an export) never share one. Returns its size in bytes;
    raises ValueError for a result XDMF cannot name, OSError for a failed write. ``cache``: see
    :func:`xdmf_text`. ``only_if_changed``: leave ``path`` untouched (its bytes and its time)
    when it already holds this document."""
    text = xdmf_text(f, result_reference(result, path.parent), frames, cache).encode()
    if only_if_changed:
        try:
            if path.read_bytes() == text:
                return len(text)
        except OSError:
            pass
    temporary = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp")
    out = open(temporary, "xb")  # noqa: SIM115 ("x": a file of this write's own, or an error)
    try:
        with out:
            out.write(text)
        os.replace(temporary, path)
    except OSError:
        temporary.unlink(missing_ok=True)
        raise
    return len(text)
