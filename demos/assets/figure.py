"""Write the animated figure the garment demos dress (committed beside this script; run it
again after changing the figure or its motion):

- figure_walk.npz: walking in place, a step every 0.55 s (skirt_walk);
- figure_turn.npz: turning from side to side, arms a little out (cape).

A 1.7 m humanoid of swept capsules (pelvis, spine, head, upper and lower arms and legs, feet),
one closed surface per part, overlapping at the joints. It is skinned: every vertex follows
its part's bone, blended with the parent bone over the part's first quarter (linear blend
skinning), so a bending hip or knee stays round. Bones turn about their joints (forward
kinematics down the skeleton). y is up, the figure faces +z. Each file holds `triangles`,
`positions` (samples, vertices, 3) [m] as float32 and `fps` (AnimatedMeshCollider.load).

    python demos/assets/figure.py
"""

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

HERE = Path(__file__).parent
FPS = 20
SECONDS = 3.3
AROUND, ALONG, CAP = 12, 7, 3       # vertices round a capsule, rings along it, per end cap

# bone: (parent, head joint, tail joint, radius at head, radius at tail) [m]
BONES = {
    "pelvis": (None, (0.0, 0.90, 0.0), (0.0, 0.98, 0.0), 0.15, 0.13),
    "spine": ("pelvis", (0.0, 1.02, 0.0), (0.0, 1.36, 0.0), 0.14, 0.15),
    "head": ("spine", (0.0, 1.40, 0.0), (0.0, 1.64, 0.01), 0.05, 0.10),
    "shoulders": ("spine", (-0.18, 1.37, -0.01), (0.18, 1.37, -0.01), 0.065, 0.065),
    "upper_arm_l": ("spine", (0.20, 1.36, 0.0), (0.24, 1.09, 0.0), 0.05, 0.042),
    "forearm_l": ("upper_arm_l", (0.24, 1.09, 0.0), (0.26, 0.84, 0.03), 0.042, 0.033),
    "upper_arm_r": ("spine", (-0.20, 1.36, 0.0), (-0.24, 1.09, 0.0), 0.05, 0.042),
    "forearm_r": ("upper_arm_r", (-0.24, 1.09, 0.0), (-0.26, 0.84, 0.03), 0.042, 0.033),
    "thigh_l": ("pelvis", (0.09, 0.90, 0.0), (0.095, 0.50, 0.01), 0.085, 0.058),
    "shin_l": ("thigh_l", (0.095, 0.50, 0.01), (0.095, 0.10, 0.0), 0.055, 0.04),
    "foot_l": ("shin_l", (0.095, 0.07, -0.02), (0.095, 0.04, 0.14), 0.04, 0.035),
    "thigh_r": ("pelvis", (-0.09, 0.90, 0.0), (-0.095, 0.50, 0.01), 0.085, 0.058),
    "shin_r": ("thigh_r", (-0.095, 0.50, 0.01), (-0.095, 0.10, 0.0), 0.055, 0.04),
    "foot_r": ("shin_r", (-0.095, 0.07, -0.02), (-0.095, 0.04, 0.14), 0.04, 0.035),
}
NAMES = list(BONES)
DEPTH = {"pelvis": 0.85, "spine": 0.8}      # the trunk is flatter front to back


def capsule(head, tail, r0, r1, depth=1.0):
    """A closed capsule from `head` to `tail` (radii r0, r1, hemispherical ends), as
    (vertices, triangles, s: each vertex's place along the bone, 0 at the head, 1 at the
    tail). `depth` squashes it along z (a trunk's oval section)."""
    head, tail = np.asarray(head, float), np.asarray(tail, float)
    axis = tail - head
    length = np.linalg.norm(axis)
    w = axis / length
    u = np.cross(w, (0.0, 0.0, 1.0) if abs(w[2]) < 0.9 else (1.0, 0.0, 0.0))
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    # rings as (offset along the bone beyond its end, radius, place s): the head's cap from
    # its pole to its equator, the straight part, the tail's cap from its equator to its pole
    latitude = np.pi / 2 * np.arange(1, CAP) / CAP
    rings = ([(-r0 * np.cos(a), r0 * np.sin(a), 0.0) for a in latitude]
             + [(0.0, r0 + (r1 - r0) * k / (ALONG - 1), k / (ALONG - 1)) for k in range(ALONG)]
             + [(r1 * np.sin(a), r1 * np.cos(a), 1.0) for a in latitude])
    angle = 2 * np.pi * np.arange(AROUND) / AROUND
    vertices, along = [head - r0 * w], [0.0]
    for offset, radius, s in rings:
        centre = head + s * axis + offset * w
        ring = (centre + radius * np.cos(angle)[:, None] * u + radius * np.sin(angle)[:, None]
                * v)
        vertices += list(ring)
        along += [s] * AROUND
    vertices.append(tail + r1 * w)
    along.append(1.0)
    vertices = np.array(vertices)
    vertices[:, 2] = head[2] + (vertices[:, 2] - head[2]) * depth
    last = len(vertices) - 1
    triangles = [(0, 1 + (k + 1) % AROUND, 1 + k) for k in range(AROUND)]
    for r in range(len(rings) - 1):
        a, b = 1 + r * AROUND, 1 + (r + 1) * AROUND
        for k in range(AROUND):
            k1 = (k + 1) % AROUND
            triangles += [(a + k, a + k1, b + k), (a + k1, b + k1, b + k)]
    top = 1 + (len(rings) - 1) * AROUND
    triangles += [(last, top + k, top + (k + 1) % AROUND) for k in range(AROUND)]
    return vertices, np.array(triangles), np.array(along)


def body():
    """(vertices, triangles, bone weights (vertices, bones)) of the figure at rest."""
    vertices, triangles, weights = [], [], []
    for index, (name, (parent, head, tail, r0, r1)) in enumerate(BONES.items()):
        v, t, s = capsule(head, tail, r0, r1, DEPTH.get(name, 1.0))
        w = np.zeros((len(v), len(BONES)))
        blend = 0.5 * (1.0 - np.clip(s / 0.25, 0.0, 1.0)) if parent else np.zeros(len(v))
        w[:, index] = 1.0 - blend
        if parent:
            w[:, NAMES.index(parent)] = blend
        triangles.append(t + sum(len(x) for x in vertices))
        vertices.append(v)
        weights.append(w)
    return np.concatenate(vertices), np.concatenate(triangles), np.concatenate(weights)


def pose(turns: dict, lift: float) -> np.ndarray:
    """Each bone's world transform (bones, 4, 4) for local turns {bone: rotation vector about
    its head joint}, the whole figure raised by `lift` [m]."""
    world = {}
    for name, (parent, head, *_rest) in BONES.items():
        local = np.eye(4)
        local[:3, :3] = Rotation.from_rotvec(turns.get(name, (0.0, 0.0, 0.0))).as_matrix()
        local[:3, 3] = np.asarray(head) - local[:3, :3] @ np.asarray(head)
        if parent is None:
            local[1, 3] += lift
            world[name] = local
        else:
            world[name] = world[parent] @ local
    return np.stack([world[n] for n in NAMES])


def walking(t: float):
    phase = 2 * np.pi * t / 1.1
    swing, knee = 0.42 * np.sin(phase), 0.55 * max(0.0, np.sin(phase + 0.5 * np.pi))
    knee_r = 0.55 * max(0.0, np.sin(phase + 1.5 * np.pi))
    return pose({"pelvis": (0.0, 0.08 * np.sin(phase), 0.0),
                 "spine": (0.03, -0.12 * np.sin(phase), 0.0),
                 "thigh_l": (-swing, 0.0, 0.0), "shin_l": (knee, 0.0, 0.0),
                 "thigh_r": (swing, 0.0, 0.0), "shin_r": (knee_r, 0.0, 0.0),
                 "upper_arm_l": (0.3 * np.sin(phase), 0.0, 0.08),
                 "upper_arm_r": (-0.3 * np.sin(phase), 0.0, -0.08),
                 "forearm_l": (-0.3, 0.0, 0.0), "forearm_r": (-0.3, 0.0, 0.0)},
                0.02 * np.cos(2 * phase))


def turning(t: float):
    yaw = 1.0 * np.sin(2 * np.pi * t / 2.2) * min(1.0, t / 0.4)
    return pose({"pelvis": (0.0, yaw, 0.0), "spine": (0.0, 0.3 * yaw, 0.0),
                 "upper_arm_l": (0.0, 0.0, 0.35), "upper_arm_r": (0.0, 0.0, -0.35),
                 "forearm_l": (-0.5, 0.0, 0.0), "forearm_r": (-0.5, 0.0, 0.0)}, 0.0)


def skinned(vertices, weights, transforms):
    """Linear blend skinning: each vertex moved by its bones' transforms, weighted."""
    homogeneous = np.column_stack([vertices, np.ones(len(vertices))])
    moved = np.einsum("bij,vj->vbi", transforms[:, :3], homogeneous)
    return np.einsum("vb,vbi->vi", weights, moved)


def write(path: Path, motion) -> None:
    vertices, triangles, weights = body()
    times = np.arange(round(SECONDS * FPS) + 1) / FPS
    positions = np.stack([skinned(vertices, weights, motion(t)) for t in times])
    np.savez_compressed(path, triangles=triangles.astype(np.int32),
                        positions=positions.astype(np.float32), fps=float(FPS))
    print(f"{path.name}: {len(vertices)} vertices, {len(triangles)} triangles, "
          f"{len(times)} samples at {FPS} fps, {path.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    write(HERE / "figure_walk.npz", walking)
    write(HERE / "figure_turn.npz", turning)
