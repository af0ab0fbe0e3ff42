"""A walk round a scene with the rig in hand, recorded with its truth, for 3D thermal mapping.

Scenes (world frame as :mod:`.scene`'s: x right, y down, z forward; the floor is y = 0, so
heights are negative y):

- :func:`machine_scene`: a machine of about a cubic metre on a skid (a pump housing, a motor
  at 45 C between hot bearings at 72 and 66 C, a warm pipe at 55 C rising and running back, a
  cold water pipe) beside an electrical cabinet with a hot terminal (a 3 cm spot at 80 C on
  its front), and a bare stainless guard (emissivity 0.3, a mirror) behind the motor that
  shows the motor and its bearings from the front right; in a 6 x 6 x 3.2 m hall at 22 C.
- :func:`room_scene`: a furnished 4 x 4 x 2.5 m room seen from inside at 21 C (walls, floor
  and ceiling within 1.5 C of it), a radiator at 55 C standing off the wall, a window in a
  reveal (glass at 10 C, emissivity 0.84, a mirror that shows the radiator from the room's
  left side), a door in its frame, skirting, a desk with a monitor and a computer at 30 C, a
  shelf unit, a cabinet, a lacquered sideboard (0.88, glossy) and a ceiling lamp at 38 C.

Every surface is directional (its emissivity falls beyond ~60 degrees from the normal, as a
smooth paint's, glass's or metal's does: :func:`~thermodepth.radiometry.fresnel_emissivity`);
the mirrors are specular (they reflect what their mirrored rays meet). The walks
(:func:`walkaround_path`, :mod:`.handheld`): round the machine at 1-2 m with one approach to
0.8 m of the hot terminal, back to the start; round the room from inside, 0.85-1.3 m from
the walls, turning to see every wall, the radiator and the window, back to the start: every
view holds a corner or furniture, so a depth camera can track it. :func:`simulate_walkaround`
records every frame of both cameras and the walk's truth (:mod:`.walk_truth`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..camera import RigidTransform
from ..frames import DepthFrame, ThermalFrame
from ..progress import Progress
from ..radiometry import ZERO_C_IN_K
from ..trajectory import Trajectory
from .cameras import depth_mode, thermal_camera
from .handheld import HandheldPath, Waypoint
from .rig import Rig
from .scene import Material, Rect, Scene, box
from .walk_truth import Hotspot, count_views, surface_samples, write_walk_truth

FloatArray = NDArray[np.float64]

K = ZERO_C_IN_K
EX, EY, EZ = np.eye(3)

WALK_START_S = 1.0
"""When a walk starts on the cameras' clock: after the thermal camera's power-on FFC."""
FFC_INTERVAL_S = 15.0
"""The thermal camera's timed FFC during a walk (a Lepton's default is 180 s): a 30 s walk
has two, at 15.25 and 30.5 s."""
THERMAL_TIME_CONSTANT_S = 0.012
"""The microbolometer's thermal time constant (:func:`~.lepton.bolometer_memory`): the
upper end of FLIR's 8-12 ms for modern microbolometers, taken for every simulated camera
(the makers give no figure; an assumption)."""


def _paint(
    temp_c: float, emissivity: float = 0.93, name: str = "", albedo: float = 0.5
) -> Material:
    """A smooth surface: its emissivity falls at oblique views (Fresnel)."""
    return Material(temp_c + K, emissivity, albedo, name, directional=True)


def _mirror(temp_c: float, emissivity: float, name: str, albedo: float = 0.5) -> Material:
    """A glossy surface: directional and specular."""
    return Material(temp_c + K, emissivity, albedo, name, directional=True, specular=True)


def _enclosure(
    x_m: tuple[float, float],
    z_m: tuple[float, float],
    height_m: float,
    temps_c: dict[str, float],
    emissivity: float = 0.93,
) -> list[Rect]:
    """Floor (y = 0), ceiling (y = -height_m) and four walls of the box x_m x z_m, each at
    its temperature in ``temps_c`` (floor, ceiling, west (-x), east (+x), south (-z),
    north (+z))."""
    (x0, x1), (z0, z1) = x_m, z_m
    cx, cz, hx, hz, hy = (x0 + x1) / 2, (z0 + z1) / 2, (x1 - x0) / 2, (z1 - z0) / 2, height_m / 2
    planes = {
        "floor": ((cx, 0.0, cz), EX, EZ, hx, hz),
        "ceiling": ((cx, -height_m, cz), EX, EZ, hx, hz),
        "west": ((x0, -hy, cz), EZ, EY, hz, hy),
        "east": ((x1, -hy, cz), EZ, EY, hz, hy),
        "south": ((cx, -hy, z0), EX, EY, hx, hy),
        "north": ((cx, -hy, z1), EX, EY, hx, hy),
    }
    return [
        Rect(np.array(c), u, v, a, b, _paint(temps_c[name], emissivity, name), name=name)
        for name, (c, u, v, a, b) in planes.items()
    ]


def machine_scene() -> Scene:
    """A machine on a skid beside an electrical cabinet in a hall (module docstring).

    Parts (centre and size in m, temperature C, emissivity): skid (0, -0.05, 0) 1.5 x 0.1 x
    0.9, 24, 0.93; pump housing (-0.2, -0.35, 0) 0.5 cube, 35; inlet on its front, 30; motor
    (0.35, -0.25, 0) 0.4 x 0.3 x 0.3, 45, 0.95, with a junction box on top at 38; bearings
    0.1 x 0.12 x 0.12 either side of it at 72 (``bearing-a``, x = 0.1) and 66 (``bearing-b``,
    x = 0.6), 0.9; warm pipe 7 cm square at 55 rising from the housing to 1.07 m, running back
    and down to the floor at z = 0.9; cold pipe 6 cm square at 16 along the back of the skid;
    stainless guard 0.7 x 0.7 m at z = 0.3 behind the motor, 23, 0.3, a mirror; cabinet
    (-1.0, -0.5, 0) 0.4 x 1.0 x 0.4, 27, 0.92, its hot terminal a 3 cm square at 80, 0.95,
    1.5 mm proud of its front face (-z) at (-0.95, -0.62). Hall 6 x 6 x 3.2 m around it,
    21.5-22.5 C, 0.93 (floor concrete 0.94); air at 22 C, RH 50 %.
    """
    rects = _enclosure(
        (-3.2, 2.8),
        (-3.0, 3.0),
        3.2,
        {"floor": 21.5, "ceiling": 22.5, "west": 22.0, "east": 21.8, "south": 22.3, "north": 21.6},
    )
    rects[0] = replace(rects[0], material=_paint(21.5, 0.94, "concrete"))
    parts: list[tuple[str, tuple[float, float, float], tuple[float, float, float], Material]] = [
        ("skid", (0.0, -0.05, 0.0), (1.5, 0.1, 0.9), _paint(24.0, 0.93, "steel")),
        ("housing", (-0.2, -0.35, 0.0), (0.5, 0.5, 0.5), _paint(35.0, 0.93, "housing")),
        ("inlet", (-0.2, -0.3, -0.3), (0.18, 0.18, 0.1), _paint(30.0, 0.93, "inlet")),
        ("motor", (0.35, -0.25, 0.0), (0.4, 0.3, 0.3), _paint(45.0, 0.95, "motor")),
        ("junction-box", (0.35, -0.45, 0.0), (0.14, 0.1, 0.14), _paint(38.0, 0.95, "junction")),
        ("bearing-a", (0.1, -0.25, 0.0), (0.1, 0.12, 0.12), _paint(72.0, 0.9, "bearing")),
        ("bearing-b", (0.6, -0.25, 0.0), (0.1, 0.12, 0.12), _paint(66.0, 0.9, "bearing")),
        ("warm-pipe-rise", (-0.2, -0.8, 0.0), (0.07, 0.4, 0.07), _paint(55.0, 0.9, "pipe")),
        ("warm-pipe", (-0.2, -1.035, 0.45), (0.07, 0.07, 0.97), _paint(55.0, 0.9, "pipe")),
        ("warm-pipe-drop", (-0.2, -0.5, 0.9), (0.07, 1.0, 0.07), _paint(55.0, 0.9, "pipe")),
        ("cold-pipe", (0.0, -0.13, 0.39), (1.5, 0.06, 0.06), _paint(16.0, 0.9, "pipe")),
        ("cabinet", (-1.0, -0.5, 0.0), (0.4, 1.0, 0.4), _paint(27.0, 0.92, "cabinet")),
    ]
    for name, centre, size, material in parts:
        rects += box(centre, size, material, name=name)
    rects += [
        Rect(
            np.array([0.45, -0.45, 0.3]),
            EX,
            EY,
            0.35,
            0.35,
            _mirror(23.0, 0.3, "stainless", albedo=0.8),
            name="guard",
        ),
        Rect(
            np.array([-0.95, -0.62, -0.2015]),
            EX,
            EY,
            0.015,
            0.015,
            _paint(80.0, 0.95, "terminal"),
            name="terminal",
        ),
    ]
    return Scene(tuple(rects), 22.0 + K, 0.5)


Extent = tuple[float, float]
"""From and to, m."""


_FACES = {"below": "+y", "above": "-y", "-x": "-x", "+x": "+x", "-z": "-z", "+z": "+z"}
"""A box's faces by the side they face (y is down: its underside is :func:`~.scene.box`'s +y
face)."""


def _block(
    x_m: Extent,
    up_m: Extent,
    z_m: Extent,
    material: Material,
    name: str,
    hidden: tuple[str, ...] = (),
) -> list[Rect]:
    """A box by its extent: x_m and z_m, and up_m, from and to how high above the floor (y is
    down, so it spans y = -up_m): furniture placed by where it stands. ``hidden``: faces
    (:data:`_FACES`: "below", "above", "-x", "+x", "-z", "+z") flat against the floor, the
    ceiling, a wall or another part, which no view can see; left out, as every rect costs
    render time (one that crosses the camera's plane costs the whole image's)."""
    (x0, x1), (h0, h1), (z0, z1) = x_m, up_m, z_m
    centre = ((x0 + x1) / 2, -(h0 + h1) / 2, (z0 + z1) / 2)
    faces = box(centre, (x1 - x0, h1 - h0, z1 - z0), material, name=name)
    left_out = {name + _FACES[side] for side in hidden}
    return [f for f in faces if f.name not in left_out]


def _sheet(x_m: Extent, up_m: Extent, z_m: Extent, material: Material, name: str) -> Rect:
    """A rect by its extent, as :func:`_block` takes it, flat along the one axis whose from
    and to are equal: a piece of wall, or a board or panel too thin (2 cm) to be worth a box."""
    lo = np.array([x_m[0], -up_m[1], z_m[0]])
    hi = np.array([x_m[1], -up_m[0], z_m[1]])
    flat = np.flatnonzero(hi - lo == 0.0)
    if len(flat) != 1:
        raise ValueError(f"sheet {name!r}: one extent must be flat, got {x_m}, {up_m}, {z_m}")
    a, b = (k for k in range(3) if k != flat[0])
    axes = np.eye(3)
    half = (hi - lo) / 2
    return Rect((lo + hi) / 2, axes[a], axes[b], half[a], half[b], material, name=name)


ROOM_HALF_M = 2.0
"""The room's walls stand at x, z = -2 and 2 m; its ceiling ROOM_HEIGHT_M up."""
ROOM_HEIGHT_M = 2.5
WINDOW_X_M = (0.2, 1.4)
"""The window's opening in the north wall: x from, to (m), and WINDOW_UP_M, from and to how
high up (m)."""
WINDOW_UP_M = (0.6, 2.0)
WINDOW_REVEAL_M = 0.15
"""How far the glass sits back from the north wall's face (the reveal), m: the recess puts
faces of all three orientations round the window, which a depth camera near it needs."""


def room_scene() -> Scene:
    """A furnished room seen from inside (module docstring).

    Room x, z in -2..2 m, 2.5 m high; floor 20.5 C (vinyl, 0.95), ceiling 22, walls 21-21.4
    but the outside (north, +z) one at 19.5 (0.93). Window: an opening in the north wall at
    x 0.2-1.4 and 0.6-2.0 m up, the glass (10 C, emissivity 0.84, a mirror) 15 cm back in
    its reveal (19 C), a window board below it (19.5, 0.9) 8 cm proud of the wall. Radiator
    on the east wall, x 1.85-1.93 (7 cm off the wall on two brackets at 40 C), z 0.6-1.6 and
    0.25-0.9 m up, 55 C, 0.93. Door on the south wall, x -1.45 to -0.55 and 2 m high (wood,
    20.8 C, 0.9), in an architrave 7 cm wide and 2 cm proud, with a steel lever (0.3).
    Skirting 8 cm high and 1.5 cm thick round the walls but the door, 20.8 C. A desk against
    the south wall (x 0.1-1.5, 0.68 m deep, top 0.75 m up on four legs, wood 0.9, 21 C) with
    a monitor on it (30 C, 0.9); a computer (30 C) on the floor beside it. An open shelf
    unit against the east wall (z -1.1 to -0.3, 0.36 m deep, 1.2 m high, two shelves, with
    books and boxes, 21 C, 0.9). A cabinet in the north-west corner (0.9 x 0.5 x 1.9 m, 21
    C, 0.9). A sideboard against the west wall, 1.2 m long, 0.9 m high, lacquered (0.88,
    glossy), 21 C. Ceiling lamp 0.3 m square at 38 C. Air at 21 C, RH 50 %.
    """
    h, top = ROOM_HALF_M, ROOM_HEIGHT_M
    rects = _enclosure(
        (-h, h),
        (-h, h),
        top,
        {"floor": 20.5, "ceiling": 22.0, "west": 21.4, "east": 21.0, "south": 21.2, "north": 19.5},
    )
    rects[0] = replace(rects[0], material=_paint(20.5, 0.95, "vinyl"))
    rects = [r for r in rects if r.name != "north"]  # rebuilt round the window's opening
    (wx0, wx1), (wu0, wu1), back = WINDOW_X_M, WINDOW_UP_M, h + WINDOW_REVEAL_M
    north, reveal = _paint(19.5, 0.93, "north"), _paint(19.0, 0.93, "reveal")
    glass = _mirror(10.0, 0.84, "glass", albedo=0.1)
    rects += [
        _sheet((-h, wx0), (0.0, top), (h, h), north, "north"),
        _sheet((wx1, h), (0.0, top), (h, h), north, "north-east-of-window"),
        _sheet((wx0, wx1), (0.0, wu0), (h, h), north, "north-below-window"),
        _sheet((wx0, wx1), (wu1, top), (h, h), north, "north-above-window"),
        _sheet((wx0, wx0), WINDOW_UP_M, (h, back), reveal, "reveal-west"),
        _sheet((wx1, wx1), WINDOW_UP_M, (h, back), reveal, "reveal-east"),
        _sheet((wx0, wx1), (wu1, wu1), (h, back), reveal, "reveal-head"),
        _sheet((wx0, wx1), WINDOW_UP_M, (back, back), glass, "window"),
    ]
    board = _paint(19.5, 0.9, "board")
    rects += _block((wx0 - 0.1, wx1 + 0.1), (wu0 - 0.03, wu0), (h - 0.08, back), board, "sill")
    # the door in its architrave, its lever
    wood = _paint(20.8, 0.9, "wood")
    rects.append(_sheet((-1.45, -0.55), (0.0, 2.0), (0.01 - h,) * 2, wood, "door"))
    frame = (-h, 0.02 - h)
    rects += _block((-1.52, -1.45), (0.0, 2.07), frame, wood, "door-frame-west", ("-z", "below"))
    rects += _block((-0.55, -0.48), (0.0, 2.07), frame, wood, "door-frame-east", ("-z", "below"))
    rects += _block((-1.45, -0.55), (2.0, 2.07), frame, wood, "door-frame-head", ("-z", "-x", "+x"))
    steel = _paint(21.0, 0.3, "steel")
    rects += _block(
        (-0.68, -0.56), (0.98, 1.02), (0.01 - h, 0.07 - h), steel, "door-lever", ("-z",)
    )
    # skirting round the walls, broken by the door: its front and top (its ends butt the
    # walls or the door's frame)
    skirting, low, thick = _paint(20.8, 0.93, "skirting"), (0.0, 0.08), 0.015
    along_x, along_z = ("-x", "+x"), ("-z", "+z")
    runs = {  # name: x, z extent; the faces against the wall and the ends
        "skirting-west": ((-h, thick - h), (-h, h), ("-x", *along_z)),
        "skirting-east": ((h - thick, h), (-h, h), ("+x", *along_z)),
        "skirting-north": ((-h, h), (h - thick, h), ("+z", *along_x)),
        "skirting-south-west": ((-h, -1.52), (-h, thick - h), ("-z", *along_x)),
        "skirting-south-east": ((-0.48, h), (-h, thick - h), ("-z", *along_x)),
    }
    for name, (x_run, z_run, hidden) in runs.items():
        rects += _block(x_run, low, z_run, skirting, name, ("below", *hidden))
    # the radiator on its brackets
    radiator = _paint(55.0, 0.93, "radiator")
    rects += _block((1.85, 1.93), (0.25, 0.9), (0.6, 1.6), radiator, "radiator")
    bracket = _paint(40.0, 0.9, "bracket")
    for k, z in enumerate((0.75, 1.45)):
        between = ("-x", "+x")  # the radiator's back, the wall
        rects += _block(
            (1.93, h), (0.7, 0.76), (z - 0.02, z + 0.02), bracket, f"bracket-{k}", between
        )
    # the desk, its monitor and the computer beside it
    rects += _block((0.1, 1.5), (0.72, 0.75), (-1.98, -1.3), wood, "desk-top")
    leg = _paint(21.0, 0.9, "leg")
    for k, (x, z) in enumerate(((0.15, -1.93), (1.45, -1.93), (0.15, -1.35), (1.45, -1.35))):
        span_x, span_z = (x - 0.025, x + 0.025), (z - 0.025, z + 0.025)
        rects += _block(span_x, (0.0, 0.72), span_z, leg, f"desk-leg-{k}", ("below", "above"))
    screen = _paint(30.0, 0.9, "screen")
    rects += _block((0.52, 1.08), (0.98, 1.32), (-1.82, -1.78), screen, "monitor")
    rects += _block((0.78, 0.82), (0.77, 0.98), (-1.86, -1.82), leg, "monitor-stand", ("below",))
    rects += _block((0.7, 0.9), (0.75, 0.77), (-1.92, -1.76), leg, "monitor-foot", ("below",))
    case = _paint(30.0, 0.93, "case")
    rects += _block((1.6, 1.8), (0.0, 0.44), (-1.925, -1.475), case, "computer", ("below",))
    # the open shelf unit on the east wall (boards 2 cm thick, as sheets), books and boxes
    shelf, paper = _paint(21.0, 0.9, "shelf"), _paint(21.0, 0.9, "paper")
    sx, (sz0, sz1) = 1.64, (-1.1, -0.3)
    rects += [
        _sheet((sx, h), (0.0, 1.2), (sz0, sz0), shelf, "shelf-side-south"),
        _sheet((sx, h), (0.0, 1.2), (sz1, sz1), shelf, "shelf-side-north"),
        _sheet((sx, h), (1.2, 1.2), (sz0, sz1), shelf, "shelf-top"),
        _sheet((sx, h), (0.45, 0.45), (sz0, sz1), shelf, "shelf-0"),
        _sheet((sx, h), (0.82, 0.82), (sz0, sz1), shelf, "shelf-1"),
    ]
    against = ("below", "+x")  # standing on a board, against the wall
    rects += _block((sx, h), (0.0, 0.08), (sz0, sz1), shelf, "shelf-plinth", (*against, "-z", "+z"))
    rects += _block((1.72, h), (0.45, 0.75), (-1.04, -0.7), paper, "books", against)
    rects += _block((1.75, h), (0.82, 1.06), (-0.6, -0.36), paper, "box-files", against)
    rects += _block((1.7, h), (0.08, 0.36), (-0.9, -0.5), paper, "storage-box", against)
    # the cabinet, the sideboard and the lamp
    cabinet, lacquer = _paint(21.0, 0.9, "cabinet"), _mirror(21.0, 0.88, "lacquer")
    rects += _block((-1.95, -1.05), (0.0, 1.9), (1.5, h), cabinet, "cabinet", ("below", "+z"))
    rects += _block((-h, -1.55), (0.0, 0.9), (-0.6, 0.6), lacquer, "sideboard", ("below", "-x"))
    lamp = _paint(38.0, 0.9, "lamp")
    rects += _block((0.35, 0.65), (2.4, top), (0.85, 1.15), lamp, "lamp", ("above",))
    return Scene(tuple(rects), 21.0 + K, 0.5)


def part_hotspot(scene: Scene, part: str) -> Hotspot:
    """The :class:`~.walk_truth.Hotspot` of the part named ``part``: the rect of that name,
    or the six faces of the box of that name (:func:`~.scene.box` names them part-x ...
    part+z)."""
    faces = {part} | {f"{part}{sign}{axis}" for sign in "-+" for axis in "xyz"}
    rects = [r for r in scene.rects if r.name in faces]
    if not rects:
        raise ValueError(f"no part {part!r} in the scene")
    corners = np.concatenate([r.boundary_m(per_edge=2) for r in rects])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    centre, size = (lo + hi) / 2, hi - lo

    def nm(v: FloatArray) -> tuple[float, float, float]:  # without the float noise
        return (round(float(v[0]), 9), round(float(v[1]), 9), round(float(v[2]), 9))

    return Hotspot(part, nm(centre), nm(size), round(rects[0].material.temp_k - K, 9))


# -- the walks ---------------------------------------------------------------------------------

_MACHINE = (-0.2, -0.45, 0.0)  # where the walk round the machine looks
_TERMINAL = (-0.95, -0.62, -0.2)
_EYE_Y = -1.35  # the rig held at chest height, 1.35 m up


def _machine_walk() -> tuple[Waypoint, ...]:
    """Round the machine anticlockwise seen from above, from its front (-z): towards the
    cabinet, in to 0.78 m of its hot terminal, out and round at 1-2 m, back to the start."""
    at = Waypoint.looking_at
    y = _EYE_Y
    return (
        at((-0.2, y, -1.7), _MACHINE),
        at((-0.75, -1.3, -1.45), _TERMINAL),
        at((-0.95, -1.05, -0.85), _TERMINAL),
        at((-1.6, -1.3, -1.2), _MACHINE),
        at((-2.2, y, -0.2), _MACHINE),
        at((-2.0, y, 0.9), _MACHINE),
        at((-1.1, y, 1.6), _MACHINE),
        at((0.0, y, 1.8), _MACHINE),
        at((1.1, y, 1.5), _MACHINE),
        at((1.8, y, 0.5), _MACHINE),
        at((1.7, y, -0.6), _MACHINE),
        at((0.9, y, -1.5), _MACHINE),
    )


def _room_walk() -> tuple[Waypoint, ...]:
    """Round the room from inside as a person surveys it, 0.85-1.3 m from the walls, turning
    once: from near the middle across to the window, in to 1.2 m of it, the radiator (to 0.7
    m of it), the shelf unit, stooping to the desk and the computer, the door, the sideboard
    and the cabinet, the window from the left (the radiator seen in it), up at the ceiling
    lamp, and back to the start.

    Every view holds a corner or furniture, and near the walls it looks down 15-40 degrees,
    so the floor is in it too: a depth camera facing a bare wall close to it (a plane fixes
    3 of the 6 degrees of freedom) loses its way, as a real one would, and a surveyor steps
    back to keep context in view.
    """
    at = Waypoint.looking_at
    y = -1.4  # chest height
    return (
        at((-0.3, y, -0.7), (0.8, -1.2, 2.15)),  # the north wall across the room
        at((0.5, y, 0.95), (0.8, -1.0, 2.15)),  # the window in its reveal, the corner
        at((1.05, -1.3, 0.75), (1.89, -0.6, 1.1)),  # the radiator, the corner
        at((1.1, y, -0.2), (1.8, -0.7, -0.75)),  # the shelf unit
        at((0.9, -1.1, -1.0), (1.6, -0.3, -1.7)),  # stooping: the desk and the computer
        at((0.0, y, -1.15), (-1.0, -0.6, -2.0)),  # the door, the south-west corner
        at((-0.85, y, -0.95), (-1.8, -0.45, -0.1)),  # the sideboard from its end
        at((-0.8, y, 0.4), (-1.5, -0.5, 1.75)),  # the cabinet in the corner
        at((-0.5, y, 1.0), (0.75, -0.95, 2.15)),  # the window from the left
        at((0.1, y, 0.3), (0.5, -2.45, 1.0)),  # up at the lamp and the ceiling
    )


SEEN_MAX_Z_M = 3.0  # the truth's view counts: surfaces seen within this depth (m)


@dataclass(frozen=True)
class WalkSite:
    """A scene to walk round: how to build it, its hot (and cold) parts, the walk's
    waypoints and its default duration (s)."""

    scene: Callable[[], Scene]
    hot_parts: tuple[str, ...]
    waypoints: Callable[[], tuple[Waypoint, ...]]
    duration_s: float


WALK_SITES: dict[str, WalkSite] = {
    "machine": WalkSite(
        machine_scene,
        ("terminal", "bearing-a", "bearing-b", "motor", "warm-pipe"),
        _machine_walk,
        30.0,
    ),
    "room": WalkSite(room_scene, ("radiator", "window", "lamp", "computer"), _room_walk, 40.0),
}
"""The walks by scene name."""


def walk_site(scene: str) -> WalkSite:
    """The walk round ``scene`` (ValueError naming the scenes there are)."""
    if scene not in WALK_SITES:
        raise ValueError(f"unknown walk scene {scene!r}; choose from {', '.join(WALK_SITES)}")
    return WALK_SITES[scene]


def walk_hotspots(scene: str) -> tuple[Hotspot, ...]:
    """The hot (and cold) parts of the walk's scene."""
    site = walk_site(scene)
    built = site.scene()
    return tuple(part_hotspot(built, p) for p in site.hot_parts)


def walkaround_path(
    scene: str, duration_s: float | None = None, seed: int = 0, start_s: float = WALK_START_S
) -> HandheldPath:
    """The walk round ``scene`` (:data:`WALK_SITES`) over ``duration_s`` (None: the scene's
    default, 30 s round the machine, 40 s round the room) from ``start_s``; ``seed`` draws
    the hand's jitter and the glances. A shorter walk covers less of the loop, out and back
    (:class:`~.handheld.HandheldPath`)."""
    site = walk_site(scene)
    return HandheldPath(site.waypoints(), duration_s or site.duration_s, seed, start_s)


def walkaround_trajectory(
    scene: str,
    duration_s: float | None = None,
    seed: int = 0,
    times_s: ArrayLike | None = None,
) -> tuple[Callable[[float], RigidTransform], Trajectory]:
    """The walk round ``scene`` (:func:`walkaround_path`): a function of time (s) giving
    ``world_from_depth`` (what :class:`~.rig.Rig`'s trajectory takes), and the truth as a
    :class:`~thermodepth.trajectory.Trajectory` at ``times_s`` (None: every 10 ms over the
    walk, from :data:`WALK_START_S`)."""
    path = walkaround_path(scene, duration_s, seed)
    if times_s is None:
        times_s = np.linspace(path.start_s, path.end_s, round(path.duration_s * 100) + 1)
    return path.pose_at, path.trajectory(times_s)


# -- the recording ---------------------------------------------------------------------------


@dataclass(frozen=True)
class WalkConfig:
    """A simulated walk: scene (:data:`WALK_SITES`); duration_s (None: the scene's); seed;
    thermal_camera, depth_mode (:mod:`.cameras`); ffc_interval_s: the thermal camera's timed
    FFC; thermal_time_constant_s: its microbolometer's; seen_spacing_m, seen_step: the truth's
    view counts, on a grid of this spacing from every seen_step-th frame."""

    scene: str = "machine"
    duration_s: float | None = None
    seed: int = 0
    thermal_camera: str = "lepton3"
    depth_mode: str = "1280x720@30"
    ffc_interval_s: float = FFC_INTERVAL_S
    thermal_time_constant_s: float = THERMAL_TIME_CONSTANT_S
    seen_spacing_m: float = 0.02
    seen_step: int = 3

    @classmethod
    def of(
        cls,
        scene: str = "machine",
        duration_s: float | None = None,
        seed: int = 0,
        camera: str | None = None,
        depth: str | None = None,
    ) -> WalkConfig:
        """The walk of the simulated cameras ``camera`` and ``depth`` (None: the Lepton 3,
        1280x720 at 30 fps)."""
        return cls(scene, duration_s, seed, thermal_camera(camera).name, depth_mode(depth).name)

    @property
    def walk_s(self) -> float:
        return self.duration_s or walk_site(self.scene).duration_s


def walk_rig(config: WalkConfig) -> tuple[Rig, HandheldPath]:
    """The rig carried on the walk of ``config``, and its path."""
    site = walk_site(config.scene)
    path = walkaround_path(config.scene, config.walk_s, config.seed)
    sensor = thermal_camera(config.thermal_camera).sensor
    rig = Rig.of_cameras(
        site.scene(),
        path.pose_at(path.start_s),
        config.thermal_camera,
        config.depth_mode,
        lepton=replace(sensor, ffc_interval_s=config.ffc_interval_s),
        seed=config.seed,
        start_s=path.start_s,
        trajectory=path.pose_at,
        thermal_time_constant_s=config.thermal_time_constant_s,
    )
    return rig, path


def walkaround_steps(config: WalkConfig) -> int:
    """The progress units of :func:`simulate_walkaround`: its frames (depth and thermal),
    then the frames whose views the truth counts."""
    rig, _ = walk_rig(config)
    n_depth, n_thermal = rig.stream_counts(config.walk_s)
    return n_depth + n_thermal + _views(n_depth, config) + _views(n_thermal, config)


def _unwatched(n: int = 1, /, description: str | None = None) -> None:
    """Progress nobody watches."""


def _views(frames: int, config: WalkConfig) -> int:
    return math.ceil(frames / config.seen_step)


def simulate_walkaround(
    out: str | Path,
    scene: str = "machine",
    duration_s: float | None = None,
    seed: int = 0,
    camera: str | None = None,
    depth: str | None = None,
    progress: Progress | None = None,
    config: WalkConfig | None = None,
) -> Path:
    """Record a walk round ``scene`` with the simulated rig into the recording ``out``:
    every depth frame (the depth camera's rate, 30 fps), every thermal frame (the thermal
    camera's rate, with telemetry, FFCs included and marked), each thermal frame paired with
    the nearest depth frame, the rig's true calibration, the settings (``source``
    ``sim:walkaround``, ``walkaround``: the :class:`WalkConfig`) and the truth (group
    ``truth``, :mod:`.walk_truth`; :func:`~.walk_truth.read_walk_truth` reads it).

    camera, depth: the simulated cameras (None: the Lepton 3, 1280x720 at 30 fps);
    ``config`` (else made of the other arguments) sets the rest. The thermal image of the
    moving rig is smeared by the microbolometer's time constant; surfaces are directional
    and mirrors reflect (module docstring).
    """
    from ..io.recording import RecordingWriter  # the simulator stands below io

    config = config or WalkConfig.of(scene, duration_s, seed, camera, depth)
    rig, path = walk_rig(config)
    tick = progress or _unwatched
    depth_times: list[float] = []
    thermal: list[tuple[float, bool]] = []  # time, in FFC
    settings = {"source": "sim:walkaround", "walkaround": asdict(config)}
    with RecordingWriter(out, rig.calibration, settings, source="sim:walkaround") as writer:
        for event in rig.stream(config.walk_s):
            writer.add(event)
            if isinstance(event, DepthFrame):
                depth_times.append(event.time_s)
                tick(1)
            elif isinstance(event, ThermalFrame):
                thermal.append((event.time_s, event.telemetry.in_ffc))
                tick(1)
        seen = _seen(rig, path, depth_times, thermal, config, tick)
        write_walk_truth(
            writer.root,
            config.scene,
            rig.scene,
            path.trajectory(depth_times),
            walk_hotspots(config.scene),
            seen,
        )
    return Path(out)


def _seen(
    rig: Rig,
    path: HandheldPath,
    depth_times: list[float],
    thermal: list[tuple[float, bool]],
    config: WalkConfig,
    tick: Progress,
) -> dict[str, object]:
    """The truth's view counts: every seen_step-th depth frame and thermal frame (those out
    of FFC) at its time's pose, over the surface grid of seen_spacing_m."""
    points, _ = surface_samples(rig.scene.geometry, config.seen_spacing_m)
    cal = rig.calibration
    # seen within the depth a map fuses by default (thermodepth map --max-range-m 3)
    limits = (rig.depth_model.min_z_m, min(rig.depth_model.max_z_m, SEEN_MAX_Z_M))

    def depth_from_world(t: float) -> RigidTransform:
        return path.pose_at(t).inverse()

    depth_views = [(depth_from_world(t),) * 2 for t in depth_times[:: config.seen_step]]
    kept = [t for t, ffc in thermal[:: config.seen_step] if not ffc]
    tick(_views(len(thermal), config) - len(kept))  # FFC frames: no view to count
    thermal_views = [
        (cal.thermal_from_depth @ depth_from_world(t), depth_from_world(t)) for t in kept
    ]
    return {
        "seen_spacing_m": config.seen_spacing_m,
        "seen_step": config.seen_step,
        "seen_range_m": limits,
        "seen_depth": count_views(rig.scene, points, depth_views, cal.depth, limits, tick),
        "seen_thermal": count_views(rig.scene, points, thermal_views, cal.thermal, limits, tick),
    }
