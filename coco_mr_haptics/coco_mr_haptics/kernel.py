"""The compiled haptic kernel: scene evaluation and one god-object step, in numba.

Why compiled: the same proxy step written with plain Python floats costs ~400 us over a scene of ten
primitives on these machines (tens of signed-distance evaluations of a tree of Python objects), which
would eat half of every millisecond. Here the scene is a flat postfix *program* (see
:mod:`coco_mr_haptics.scene`) evaluated with a small stack, and a whole step - traces, projections,
sliding, friction and force - is one call from Python that allocates nothing.

The algorithm (Salisbury and Tarr 1997, with CHAI3D's friction cone), in words:

- ``f(p)`` is a signed distance (negative inside), or for combinations a lower bound of it, so a ball
  of radius ``f(p)`` around ``p`` holds no surface. Every proxy move through space is *sphere traced*
  with that bound: it can stop early, never cross a surface; a device that jumps through a 2 mm wall
  in one millisecond leaves the proxy on the side it came from.
- In contact the proxy slides on the tangent plane towards the device in sub-steps of at most
  ``max_slide`` and is put back on ``f = 0`` by Newton steps along the gradient. A sub-step shorter
  than half the thinnest wall cannot come back on the far side; a projection that moves the proxy
  further than two sub-steps is refused (it would have jumped to another sheet of the surface).
- The proxy leaves the surface only when the device is outside and the straight path from the device
  back to the proxy is free (a trace from the device reaches it).
- Friction: while the force the proxy would give from where it is lies inside the cone of
  ``static_friction`` (``dynamic_friction`` once it slides), it does not move (sticks); otherwise it is
  put on the dynamic cone, trailing the device, so the tangential force is ``dynamic_friction`` times
  the normal one.
- Force = stiffness (proxy - device) - damping (v . n) n, never attractive along the normal, clamped
  to ``max_force``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Opcodes of a scene program: primitives below CSG_BASE, combinations above.
SPHERE, PLANE, BOX, CYLINDER, CAPSULE, TORUS = 0, 1, 2, 3, 4, 5
CSG_BASE = 10
UNION, INTERSECTION, DIFFERENCE = 10, 11, 12

PARAMS = 20
"""Floats per primitive row: rotation (9, row-major), translation (3), shape parameters (up to 8)."""
SHAPE = 12
"""Index of the first shape parameter in a row."""

# Indices into a proxy state vector.
PX, PY, PZ, NX, NY, NZ, CONTACT, STICKING, STARTED, FX, FY, FZ, DEPTH = range(13)
STATE = 13

# Indices into a material vector.
K, B, MU_S, MU_D, F_MAX, SLIDE, ITERATIONS = range(7)
MATERIAL = 7

SURFACE_TOLERANCE = 1e-9
"""Metres: a sphere trace stops this close to the surface."""
PROJECTION_TOLERANCE = 1e-12
"""Metres: projections stop once ``|f|`` is below this."""
RELEASE_TOLERANCE = 1e-7
"""Metres: how close a trace from the device must come to the proxy to see it."""
TRACE_STEPS = 64
"""Sphere-trace iterations per move; a move that needs more stops early, still in free space."""


@njit(cache=True, nogil=True)
def _primitive(code, row, x, y, z):
    """Signed distance and gradient of one primitive in its own frame."""
    if code == SPHERE:
        length = math.sqrt(x * x + y * y + z * z)
        if length < 1e-15:
            return -row[SHAPE], 0.0, 0.0, 1.0
        return length - row[SHAPE], x / length, y / length, z / length
    if code == PLANE:
        nx, ny, nz = row[SHAPE], row[SHAPE + 1], row[SHAPE + 2]
        return x * nx + y * ny + z * nz - row[SHAPE + 3], nx, ny, nz
    if code == BOX:
        qx, qy, qz = abs(x) - row[SHAPE], abs(y) - row[SHAPE + 1], abs(z) - row[SHAPE + 2]
        if qx > 0.0 or qy > 0.0 or qz > 0.0:
            ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
            length = math.sqrt(ox * ox + oy * oy + oz * oz)
            return (length, math.copysign(ox, x) / length, math.copysign(oy, y) / length,
                    math.copysign(oz, z) / length)
        if qx >= qy and qx >= qz:
            return qx, math.copysign(1.0, x), 0.0, 0.0
        if qy >= qz:
            return qy, 0.0, math.copysign(1.0, y), 0.0
        return qz, 0.0, 0.0, math.copysign(1.0, z)
    if code == CYLINDER:
        rho = math.sqrt(x * x + y * y)
        ux, uy = (x / rho, y / rho) if rho > 1e-15 else (1.0, 0.0)
        qr, qz = rho - row[SHAPE], abs(z) - row[SHAPE + 1]
        sz = math.copysign(1.0, z)
        if qr > 0.0 or qz > 0.0:
            orr, oz = max(qr, 0.0), max(qz, 0.0)
            length = math.sqrt(orr * orr + oz * oz)
            return length, ux * orr / length, uy * orr / length, sz * oz / length
        if qr >= qz:
            return qr, ux, uy, 0.0
        return qz, 0.0, 0.0, sz
    if code == CAPSULE:
        half = row[SHAPE + 1]
        dz = z - min(max(z, -half), half)
        length = math.sqrt(x * x + y * y + dz * dz)
        if length < 1e-15:
            return -row[SHAPE], 1.0, 0.0, 0.0
        return length - row[SHAPE], x / length, y / length, dz / length
    # TORUS
    rho = math.sqrt(x * x + y * y)
    ux, uy = (x / rho, y / rho) if rho > 1e-15 else (1.0, 0.0)
    qr = rho - row[SHAPE]
    length = math.sqrt(qr * qr + z * z)
    if length < 1e-15:
        return -row[SHAPE + 1], ux, uy, 0.0
    return length - row[SHAPE + 1], ux * qr / length, uy * qr / length, z / length


@njit(cache=True, nogil=True)
def evaluate(ops, prm, stack, x, y, z):
    """``(f, gx, gy, gz)`` of the scene program at a point; ``stack`` is scratch (depth x 4)."""
    top = 0
    for i in range(ops.shape[0]):
        code = ops[i, 0]
        if code < CSG_BASE:
            row = prm[ops[i, 1]]
            dx, dy, dz = x - row[9], y - row[10], z - row[11]
            f, gx, gy, gz = _primitive(code, row,
                                       row[0] * dx + row[3] * dy + row[6] * dz,
                                       row[1] * dx + row[4] * dy + row[7] * dz,
                                       row[2] * dx + row[5] * dy + row[8] * dz)
            stack[top, 0] = f
            stack[top, 1] = row[0] * gx + row[1] * gy + row[2] * gz
            stack[top, 2] = row[3] * gx + row[4] * gy + row[5] * gz
            stack[top, 3] = row[6] * gx + row[7] * gy + row[8] * gz
            top += 1
            continue
        base = top - ops[i, 1]
        best = base
        sign = 1.0
        for j in range(base + 1, top):
            value = stack[j, 0]
            if code == UNION:
                if value < stack[best, 0] * sign:
                    best, sign = j, 1.0
            elif code == INTERSECTION:
                if value > stack[best, 0] * sign:
                    best, sign = j, 1.0
            elif -value > stack[best, 0] * sign:
                best, sign = j, -1.0
        if best != base or sign < 0.0:
            for c in range(4):
                stack[base, c] = sign * stack[best, c]
        top = base + 1
    return stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3]


@njit(cache=True, nogil=True)
def distances(ops, prm, stack, points):
    """Signed distance of each row of ``points`` (N x 3)."""
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        out[i] = evaluate(ops, prm, stack, points[i, 0], points[i, 1], points[i, 2])[0]
    return out


@njit(cache=True, nogil=True)
def _trace(ops, prm, stack, ax, ay, az, bx, by, bz):
    """Sphere trace from ``a`` towards ``b``: (distance travelled, |b - a|, hit a surface)."""
    dx, dy, dz = bx - ax, by - ay, bz - az
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return 0.0, 0.0, False
    ux, uy, uz = dx / length, dy / length, dz / length
    travelled = 0.0
    for _ in range(TRACE_STEPS):
        f = evaluate(ops, prm, stack, ax + ux * travelled, ay + uy * travelled, az + uz * travelled)[0]
        if f < SURFACE_TOLERANCE:
            return travelled, length, True
        travelled += f
        if travelled >= length:
            return length, length, False
    return travelled, length, False


@njit(cache=True, nogil=True)
def project(ops, prm, stack, x, y, z):
    """Newton steps along the gradient onto ``f = 0`` (one step is exact for a true distance)."""
    for _ in range(6):
        f, gx, gy, gz = evaluate(ops, prm, stack, x, y, z)
        if abs(f) < PROJECTION_TOLERANCE:
            break
        norm2 = gx * gx + gy * gy + gz * gz
        if norm2 == 0.0:
            break
        scale = f / norm2
        x, y, z = x - gx * scale, y - gy * scale, z - gz * scale
    return x, y, z


@njit(cache=True, nogil=True)
def _slide(ops, prm, stack, state, slide, iterations, x, y, z):
    """Constrained motion on the surface towards the point nearest the device."""
    px, py, pz = state[PX], state[PY], state[PZ]
    for _ in range(iterations):
        f, nx, ny, nz = evaluate(ops, prm, stack, px, py, pz)
        dx, dy, dz = x - px, y - py, z - pz
        dn = dx * nx + dy * ny + dz * nz
        if dn < 0.0:  # the usual case: along the tangent plane
            dx, dy, dz = dx - dn * nx, dy - dn * ny, dz - dn * nz
        # else the device is on the free side of this tangent plane yet hidden from the proxy (a
        # concave region): move straight towards it, the projection keeps the proxy on the surface.
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if length < SURFACE_TOLERANCE:
            break
        step = min(slide, length) / length
        qx, qy, qz = project(ops, prm, stack, px + dx * step, py + dy * step, pz + dz * step)
        moved = math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
        if moved > 2.0 * slide or moved < SURFACE_TOLERANCE:
            break  # the projection jumped to another sheet of the surface, or no progress
        px, py, pz = qx, qy, qz
    state[PX], state[PY], state[PZ] = px, py, pz


@njit(cache=True, nogil=True)
def _friction(ops, prm, stack, state, material, ox0, oy0, oz0, x, y, z):
    """Stick at the previous proxy ``o`` inside the friction cone, else trail on the dynamic cone."""
    gx, gy, gz = state[PX], state[PY], state[PZ]  # the frictionless goal
    f, nx, ny, nz = evaluate(ops, prm, stack, gx, gy, gz)
    depth = (gx - x) * nx + (gy - y) * ny + (gz - z) * nz
    if depth <= 0.0:
        state[STICKING] = 0.0
        return
    ox, oy, oz = ox0 - gx, oy0 - gy, oz0 - gz
    offset = math.sqrt(ox * ox + oy * oy + oz * oz)
    mu = material[MU_S] if state[STICKING] > 0.0 else material[MU_D]
    if offset <= mu * depth:
        state[PX], state[PY], state[PZ] = project(ops, prm, stack, ox0, oy0, oz0)
        state[STICKING] = 1.0
        return
    state[STICKING] = 0.0
    reach = material[MU_D] * depth / offset
    if reach > 0.0:
        state[PX], state[PY], state[PZ] = project(ops, prm, stack, gx + ox * reach, gy + oy * reach,
                                                  gz + oz * reach)


@njit(cache=True, nogil=True)
def _move(ops, prm, stack, state, material, x, y, z):
    """The proxy's new position for the device at ``(x, y, z)``; sets CONTACT."""
    if state[STARTED] == 0.0:
        # No history: start at the device if it is outside, else at the nearest surface point.
        state[STARTED] = 1.0
        state[STICKING] = 0.0
        if evaluate(ops, prm, stack, x, y, z)[0] >= 0.0:
            state[PX], state[PY], state[PZ], state[CONTACT] = x, y, z, 0.0
            return
        state[PX], state[PY], state[PZ] = project(ops, prm, stack, x, y, z)
        state[CONTACT] = 1.0
    px, py, pz = state[PX], state[PY], state[PZ]
    if state[CONTACT] != 0.0:
        # The surface may have moved since the last cycle (a frame, a new cloud structure): the
        # proxy is put back on it from where it was, never re-found from scratch.
        px, py, pz = project(ops, prm, stack, px, py, pz)
        state[PX], state[PY], state[PZ] = px, py, pz
    if state[CONTACT] == 0.0:
        travelled, length, hit = _trace(ops, prm, stack, px, py, pz, x, y, z)
        if not hit:
            if travelled >= length:
                state[PX], state[PY], state[PZ] = x, y, z
            else:  # grazing a surface: the trace ran out of steps, still in free space
                s = travelled / length
                state[PX], state[PY], state[PZ] = px + (x - px) * s, py + (y - py) * s, pz + (z - pz) * s
            return
        s = travelled / length
        px, py, pz = project(ops, prm, stack, px + (x - px) * s, py + (y - py) * s, pz + (z - pz) * s)
        state[PX], state[PY], state[PZ] = px, py, pz
        state[CONTACT] = 1.0
        state[STICKING] = 1.0  # it lands at rest: leaving the spot takes the static cone
    elif evaluate(ops, prm, stack, x, y, z)[0] > 0.0:
        travelled, length, hit = _trace(ops, prm, stack, x, y, z, px, py, pz)
        if length - travelled <= RELEASE_TOLERANCE:
            state[PX], state[PY], state[PZ] = x, y, z
            state[CONTACT] = 0.0
            state[STICKING] = 0.0
            return
    _slide(ops, prm, stack, state, material[SLIDE], int(material[ITERATIONS]), x, y, z)
    if material[MU_S] > 0.0 or material[MU_D] > 0.0:
        _friction(ops, prm, stack, state, material, px, py, pz, x, y, z)


@njit(cache=True, nogil=True)
def step(ops, prm, stack, state, material, x, y, z, vx, vy, vz):
    """One haptic step: move the proxy, then the force on the device into ``state[FX:FZ+1]``.

    Returns True in contact. ``state[DEPTH]`` is the penetration (device to proxy along the normal).
    """
    _move(ops, prm, stack, state, material, x, y, z)
    if state[CONTACT] == 0.0:
        state[FX] = state[FY] = state[FZ] = state[DEPTH] = 0.0
        return False
    f, nx, ny, nz = evaluate(ops, prm, stack, state[PX], state[PY], state[PZ])
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if norm > 0.0:
        nx, ny, nz = nx / norm, ny / norm, nz / norm
    state[NX], state[NY], state[NZ] = nx, ny, nz
    k = material[K]
    fx, fy, fz = k * (state[PX] - x), k * (state[PY] - y), k * (state[PZ] - z)
    normal = fx * nx + fy * ny + fz * nz
    state[DEPTH] = normal / k if k > 0.0 else 0.0
    # A surface pushes, it never pulls: damping may not make the normal force attractive.
    damped = max(normal - material[B] * (vx * nx + vy * ny + vz * nz), 0.0)
    change = damped - normal
    fx, fy, fz = fx + change * nx, fy + change * ny, fz + change * nz
    magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
    if magnitude > material[F_MAX]:
        scale = material[F_MAX] / magnitude
        fx, fy, fz = fx * scale, fy * scale, fz * scale
    state[FX], state[FY], state[FZ] = fx, fy, fz
    return True


def new_state() -> np.ndarray:
    return np.zeros(STATE)
