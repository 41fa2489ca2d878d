"""Write (or check) ``scenes/objects/jar.xml``: the bundled mesh object, a convex jar.

The jar is the convex hull of circles (:data:`RINGS`: height above its bottom and radius [m])
sampled at :data:`SIDES` points each: a body 64 mm across, a shoulder narrowing to a 44 mm
lid, 72 mm tall, 0.15 kg. MuJoCo collides a mesh as its convex hull, so the vertices given
are the shape. The mesh is inline (``<mesh vertex=...>``): the file needs no other.

    python scripts/make_jar.py --write   # write the file
    python scripts/make_jar.py           # exit 1 if the file differs from what it writes
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parent.parent / "scenes" / "objects" / "jar.xml"
SIDES = 24
RINGS = ((0.0, 0.032), (0.055, 0.032), (0.066, 0.022), (0.072, 0.022))
HEIGHT = RINGS[-1][0]
MASS = 0.15


def vertices() -> list[tuple[float, float, float]]:
    """The rings' points, in the body frame (origin at the jar's mid-height) [m]."""
    out = []
    for z, r in RINGS:
        for k in range(SIDES):
            a = 2.0 * math.pi * (k + 0.5) / SIDES
            out.append((r * math.cos(a), r * math.sin(a), z - 0.5 * HEIGHT))
    return out


def jar_xml() -> str:
    """The MJCF text of the jar."""
    text = " ".join(f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices())
    across, tall, lid = (1000 * v for v in (2 * RINGS[0][1], HEIGHT, 2 * RINGS[-1][1]))
    return f"""<!-- A jar for `pickplace run --object jar`, written by scripts/make_jar.py (do not
     edit): a convex mesh {across:.0f} mm across and {tall:.0f} mm tall with a {lid:.0f} mm lid,
     {MASS:g} kg, standing upright (its axis along the body's z). -->
<mujoco model="jar">
  <asset>
    <mesh name="jar" vertex="{text}"/>
  </asset>
  <worldbody>
    <body name="jar">
      <freejoint name="jar"/>
      <geom name="jar" type="mesh" mesh="jar" mass="{MASS:g}" rgba="0.2 0.6 0.3 1"
        friction="1 0.005 0.0001" condim="3"/>
    </body>
  </worldbody>
</mujoco>
"""


def main(argv: list[str] | None = None) -> int:
    """Write the file (``--write``) or check that it is what this script writes."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="write the file")
    args = parser.parse_args(argv)
    text = jar_xml()
    if args.write:
        OUT.write_text(text)
        return 0
    if not OUT.is_file() or OUT.read_text() != text:
        print(f"{OUT} differs from what scripts/make_jar.py writes", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
