"""Test objects in the object catalogue's format (contract section 1) until the objects stage lands: trimesh
primitives of known size, as items with the fields the grasp stage reads (ObjectItem's)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh


@dataclass(frozen=True)
class TestItem:
    id: str
    category: str
    vertices: np.ndarray
    faces: np.ndarray
    size_m: tuple
    grasps: tuple = ()


def item(id: str, category: str, mesh: trimesh.Trimesh, grasps=()) -> TestItem:
    v = np.asarray(mesh.vertices, np.float64)
    v = v - (v.min(0) + v.max(0)) / 2
    return TestItem(id, category, v, np.asarray(mesh.faces, np.int32), tuple(np.ptp(v, axis=0)), tuple(grasps))


def sphere(radius: float = 0.035, grasps=("power_sphere",)) -> TestItem:
    return item("ball_test", "ball", trimesh.creation.icosphere(4, radius), grasps)


def cylinder(radius: float = 0.033, height: float = 0.12, grasps=("large_diameter",)) -> TestItem:
    return item("can_test", "bottle", trimesh.creation.cylinder(radius, height, sections=48), grasps)


def box(extents=(0.07, 0.14, 0.008), grasps=("prismatic_4_finger",)) -> TestItem:
    return item("phone_test", "phone", trimesh.creation.box(extents), grasps)


def crumb() -> TestItem:
    """A 4 mm ball asked for a whole-hand grasp and for a grasp type the taxonomy does not have: both dropped."""
    return item("crumb_test", "ball", trimesh.creation.icosphere(2, 0.002), ("power_sphere", "no_such_grasp"))


def lump(size: float = 0.07) -> TestItem:
    """A convex lump with no mirror symmetry (the hull of seeded random points): its left grasps are refitted."""
    points = np.random.default_rng(5).normal(size=(40, 3)) * np.array([1.0, 0.9, 0.85])
    hull = trimesh.convex.convex_hull(points * size / np.ptp(points, axis=0).max())
    return item("lump_test", "ball", hull, ("precision_sphere", "tripod"))
