#!/usr/bin/env python3
"""Survey of the n-gons in OBJ files: how many faces of four or more distinct corners a fan
(0, i, i+1) triangulates outside themselves, and by how much. Written from the definitions, without
lodstream's code, for the figures in README ("Polygons") and to check `lodstream info`'s
polygons_concave. Standard library only.

A face's ring is its corners less each corner equal to the previous one (the first kept); faces whose ring
has m >= 4 distinct vertices are surveyed. In the face's Newell plane (projected along the normal's largest
axis, counter-clockwise), the fan is inside when none of its triangles turns clockwise by more than
1e-12 * extent^2 (the tolerance of core/polygon_triangulation.cpp); otherwise the face is concave for the
fan, and either simple (no two edges cross: lodstream triangulates it inside itself, `polygons_concave`)
or self-intersecting (no inside: lodstream keeps the fan). The fan's excess on a simple concave face is
sum(|fan triangle areas|) - polygon area: the area its triangles cover outside the face or twice inside
it (a fan's signed areas always sum to the polygon's area).

usage: polygon_survey.py FILE.obj|DIR...   (prints one line per file with n-gons, then the totals)
"""
import math
import os
import sys


def newell(p):
    n = len(p)
    ox, oy, oz = p[0]
    nx = ny = nz = 0.0
    for i in range(n):
        j = (i + 1) % n
        xi, yi, zi = p[i][0] - ox, p[i][1] - oy, p[i][2] - oz
        xj, yj, zj = p[j][0] - ox, p[j][1] - oy, p[j][2] - oz
        nx += (yi - yj) * (zi + zj)
        ny += (zi - zj) * (xi + xj)
        nz += (xi - xj) * (yi + yj)
    return nx, ny, nz


def survey_face(p):
    """(concave, polygon area, fan excess area, concave and simple) in the face's plane; None when it has
    no plane."""
    normal = newell(p)
    k = max(range(3), key=lambda a: (abs(normal[a]), -a))
    nk = normal[k]
    if nk == 0 or not math.isfinite(nk):
        return None
    a, b = (k + 1) % 3, (k + 2) % 3
    mirror = 1.0 if nk > 0 else -1.0
    uv = [(q[a] - p[0][a], mirror * (q[b] - p[0][b])) for q in p]
    us = [u for u, _ in uv] + [0.0]
    vs = [v for _, v in uv] + [0.0]
    extent = max(max(us) - min(us), max(vs) - min(vs))
    eps = 1e-12 * extent * extent
    if abs(nk) <= eps:
        return None
    scale = math.sqrt(sum(c * c for c in normal)) / abs(nk)  # projected area -> plane area

    def cross(i, j, m):
        return (uv[j][0] - uv[i][0]) * (uv[m][1] - uv[i][1]) - (uv[j][1] - uv[i][1]) * (uv[m][0] - uv[i][0])

    fan = [cross(0, i, i + 1) for i in range(1, len(p) - 1)]
    concave = any(c < -eps for c in fan)
    area = sum(fan) / 2 * scale
    excess = sum(abs(c) for c in fan) / 2 * scale - area
    return concave, area, excess, concave and simple(uv, eps)


def simple(uv, eps):
    """No two edges cross at a point inside both (by more than eps on each side)."""
    n = len(uv)

    def cross(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    def opposite(d1, d2):
        return (d1 > eps and d2 < -eps) or (d1 < -eps and d2 > eps)

    for i in range(n):
        a, b = uv[i], uv[(i + 1) % n]
        for j in range(i + 2, n):
            if (j + 1) % n == i:
                continue
            c, d = uv[j], uv[(j + 1) % n]
            if opposite(cross(a, b, c), cross(a, b, d)) and opposite(cross(c, d, a), cross(c, d, b)):
                return False
    return True


def obj_faces(path):
    positions = []
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("utf-8", "replace").split("#")[0].split()
            if not line:
                continue
            if line[0] == "v":
                positions.append(tuple(float(x) for x in line[1:4]))
            elif line[0] == "f" and len(line) >= 5:
                refs = []
                for token in line[1:]:
                    i = int(token.split("/")[0])
                    refs.append(i - 1 if i > 0 else len(positions) + i)
                ring = [refs[0]]
                for r in refs[1:]:
                    if r != ring[-1]:
                        ring.append(r)
                while len(ring) > 1 and ring[-1] == ring[0]:
                    ring.pop()
                if len(ring) >= 4 and len(set(ring)) == len(ring):
                    yield ring, positions


def survey(path):
    faces = concave = no_plane = crossing = 0
    concave_area = excess = 0.0
    for ring, positions in obj_faces(path):
        faces += 1
        r = survey_face([positions[i] for i in ring])
        if r is None:
            no_plane += 1
        elif r[3]:
            concave += 1
            concave_area += r[1]
            excess += r[2]
        elif r[0]:
            crossing += 1
    return faces, concave, no_plane, concave_area, excess, crossing


def main():
    paths = []
    for arg in sys.argv[1:]:
        if os.path.isdir(arg):
            for root, _, names in os.walk(arg):
                paths += [os.path.join(root, n) for n in names if n.lower().endswith(".obj")]
        else:
            paths.append(arg)
    total = [0, 0, 0, 0.0, 0.0, 0]
    files_with = 0
    for path in sorted(paths):
        r = survey(path)
        if r[0] == 0:
            continue
        files_with += 1
        total = [t + x for t, x in zip(total, r)]
        share = f"{100 * r[4] / r[3]:.1f} %" if r[3] else "-"
        print(f"{path}: {r[0]} faces of 4+ corners, {r[1]} simple and concave for the fan, {r[5]} concave "
              f"and self-intersecting, {r[2]} without a plane, fan excess {r[4]:.6g} on {r[3]:.6g} of "
              f"simple concave-face area ({share})")
    share = f"{100 * total[4] / total[3]:.1f} %" if total[3] else "-"
    print(f"total: {len(paths)} files, {files_with} with faces of 4+ corners: {total[0]} such faces, {total[1]} "
          f"simple and concave for the fan, {total[5]} concave and self-intersecting, {total[2]} without a "
          f"plane, fan excess {total[4]:.6g} on {total[3]:.6g} of simple concave-face area ({share})")


if __name__ == "__main__":
    main()
