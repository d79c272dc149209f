"""What a user sees of the surfacer on irregular particles and thin sheets (CPU, small):
random samples surface within about a tenth of a particle spacing, and a one-particle-thick
sheet of water stays one closed sheet with anisotropic kernels."""

import numpy as np
import pytest

from mpmfx.bench.surface_cases import BOX_HALF, OURS, measure_sheet, mesh_stats, sample_shape, shape_sdf
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles

pytest.importorskip("warp")


def test_random_sphere_within_an_eighth_of_a_spacing_with_the_shot_setting():
    # the surface stage's setting ("fine"), 20k uniformly random particles: measured 0.105 h mean,
    # 0.52 h max, one piece, volume -1.3 % (eight steps of the curvature flow; five limited blur
    # passes gave 0.112 h, 0.59 h, -0.9 %; none 0.140 h): smoothing shrinks a small curved body
    # by its curvature, here 17 spacings in radius
    x, h = sample_shape("sphere", 20_000, "random")
    setting = dict(OURS["fine"])
    params = SurfaceParams(
        PARTICLE_RADIUS_PER_SPACING * h, voxel_size=setting.pop("voxel_h") * h, dense_output=False, **setting
    )
    mesh = surface_particles(x, None, params, device="cpu").mesh
    err = np.abs(shape_sdf("sphere")[0](mesh.vertices.astype(np.float64))) / h
    volume, pieces = mesh_stats(mesh.vertices, mesh.faces)
    assert err.mean() < 0.12, f"mean vertex error {err.mean():.3f} h"
    assert err.max() < 1.0, f"max vertex error {err.max():.2f} h"
    assert pieces == 1
    assert abs(volume / shape_sdf("sphere")[1] - 1.0) < 0.015


def test_thin_random_sheet_stays_one_sheet_with_anisotropic_kernels():
    # a disc one spacing thick, 3000 random particles, "fast": isotropic kernels measured 40 holes
    # through it, anisotropic 1 (thickness +0.40 h)
    iso = measure_sheet(3000, "random", label="fast", device="cpu")
    aniso = measure_sheet(3000, "random", label="fast", device="cpu", anisotropic=True)
    assert aniso["components"] == 1 and aniso["open_edges"] == 0
    assert aniso["holes"] <= 3, f"{aniso['holes']} holes with anisotropic kernels"
    assert iso["holes"] > 5 * max(aniso["holes"], 1), (iso["holes"], aniso["holes"])
    assert abs(aniso["thickness_err"]) < 0.6, f"thickness error {aniso['thickness_err']:+.2f} (x h)"


def test_thin_random_sheet_stays_nearly_whole_at_the_shot_setting():
    # "fine", a disc one spacing thick, 3000 random particles: the curvature flow smooths along
    # the surface only, so it closes the raw field's gaps (57 holes unsmoothed) where the blur
    # it replaced pinched them into more (measured: flow 11 holes, anisotropic 1; blur 68 / 13)
    iso = measure_sheet(3000, "random", label="fine", device="cpu")
    aniso = measure_sheet(3000, "random", label="fine", device="cpu", anisotropic=True)
    for row in (iso, aniso):
        assert row["components"] == 1 and row["open_edges"] == 0
    assert iso["holes"] <= 20, f"{iso['holes']} holes through the sheet"
    assert aniso["holes"] <= 3, f"{aniso['holes']} holes with anisotropic kernels"


def test_smoothing_does_not_thin_a_flat_sheet():
    # one lattice layer at "fine": thirty smoothing steps move its faces by 0.03 h (thickness
    # +0.166 h unsmoothed, +0.136 h smoothed); thirty passes of a [1 2 1]/4 blur instead of the
    # flow would take it to -0.133 h, held only by the inward limit
    unsmoothed = measure_sheet(
        3000, "lattice", label="round", device="cpu", smooth_iters=0
    )  # sharp edges need smoothing
    smoothed = measure_sheet(3000, "lattice", label="fine", device="cpu", smooth_iters=30)
    assert smoothed["holes"] == 0 and smoothed["components"] == 1
    assert abs(smoothed["thickness_err"] - unsmoothed["thickness_err"]) < 0.1, (smoothed, unsmoothed)


def test_anisotropic_must_be_a_bool():
    with pytest.raises(ValueError, match="SurfaceParams.anisotropic"):
        SurfaceParams(0.01, anisotropic="yes")


@pytest.mark.parametrize("fill", [1.5, 6.0])
def test_a_random_box_face_lands_on_the_face_wherever_it_cuts_its_block(fill):
    # the shot setting, 20k uniformly random particles in the bench's box, shifted along x so
    # that the +x face cuts its 8^3-voxel block `fill` voxels from the block's inner side. An
    # INSIDE tile 1-3 voxels under the face would push patches of it a voxel (0.5 h) outward
    # (grid.dense_rule keeps INSIDE tiles deeper: +0.04 h at both fills)
    x, h = sample_shape("box", 20_000, "random")
    setting = dict(OURS["fine"])
    voxel = setting.pop("voxel_h") * h
    params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False, **setting)
    face = BOX_HALF[0] / voxel  # the +x face in voxel index units (blocks start at multiples of 8)
    shift = (8.0 * np.ceil(face / 8.0) - 8.0 + fill - face) * voxel
    x[:, 0] += shift
    v = surface_particles(x, None, params, device="cpu").mesh.vertices.astype(np.float64)
    v[:, 0] -= shift
    on_face = (v[:, 0] > 0) & np.all(np.abs(v[:, 1:]) < BOX_HALF[1:] - 4 * h, axis=1)
    height = (v[on_face, 0] - BOX_HALF[0]) / h
    assert on_face.sum() > 500
    assert abs(height.mean()) < 0.1, f"+x face at {height.mean():+.3f} h (block fill {fill} voxels)"


def test_closing_the_voids_brings_random_surfaces_closer_without_growing_them():
    # SurfaceParams.close_voids = one spacing, "fast", 20k random sphere: a ball rolled over the
    # outside fills the dents of sample voids before the smoothing (close.close_voids); without /
    # with it: 0.126 / 0.117 h mean, 0.78 / 0.59 h max, volume -0.6 / -0.4 % (ungated: 0.109 h,
    # 0.57 h, -0.5 %)
    x, h = sample_shape("sphere", 20_000, "random")
    setting = dict(OURS["fast"])
    voxel = setting.pop("voxel_h") * h
    rows = []
    for close in (0.0, h):
        params = SurfaceParams(
            PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False, close_voids=close, **setting
        )
        mesh = surface_particles(x, None, params, device="cpu").mesh
        err = np.abs(shape_sdf("sphere")[0](mesh.vertices.astype(np.float64))) / h
        volume, pieces = mesh_stats(mesh.vertices, mesh.faces)
        rows.append((err.mean(), err.max(), volume / shape_sdf("sphere")[1] - 1.0, pieces))
    (mean0, max0, _, _), (mean1, max1, vol1, pieces1) = rows
    assert mean1 < mean0 - 0.005, f"mean vertex error {mean0:.4f} -> {mean1:.4f} h"
    assert max1 <= max0, f"max vertex error {max0:.3f} -> {max1:.3f} h"
    assert pieces1 == 1 and abs(vol1) < 0.01, (pieces1, vol1)


def test_close_voids_must_be_a_non_negative_length():
    with pytest.raises(ValueError, match="close_voids"):
        SurfaceParams(0.01, close_voids=-0.01)


@pytest.mark.parametrize("label", ["fast", "fine"])
def test_closing_the_voids_leaves_a_lattice_box_where_it_is(label):
    # a flat lattice face has no void to fill; ungated, the closing would move the 20k lattice
    # box's faces out and erode its edges (mean error "fast" 0.029 / 0.041 h, "fine" 0.056 /
    # 0.073 h without / with it); only fills deeper than close.CLOSE_GATE x the radius are kept,
    # so the mesh is the one without the closing
    x, h = sample_shape("box", 20_000, "lattice")
    setting = dict(OURS[label])
    voxel = setting.pop("voxel_h") * h
    errs = []
    for close in (0.0, h):
        params = SurfaceParams(
            PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False, close_voids=close, **setting
        )
        mesh = surface_particles(x, None, params, device="cpu").mesh
        errs.append(np.abs(shape_sdf("box")[0](mesh.vertices.astype(np.float64))).mean() / h)
    assert errs[1] <= errs[0] + 0.001, f"lattice box mean vertex error {errs[0]:.4f} -> {errs[1]:.4f} h"


@pytest.mark.parametrize("label", ["fast", "fine"])
def test_a_lattice_box_face_stays_on_the_face_through_the_blur(label):
    # 20k lattice box: the faces away from the edges, signed height in h. The distance the blur
    # starts from would have a kink at the zero crossing (the raw field's slope across it is 0.97
    # on a flat lattice face), and each of the five "fine" passes would move the face out across
    # it (+0.0148 h "fine", +0.0030 "fast"); with the crossing voxels started at their distance
    # to the plane through the crossings, +0.0049 / +0.0030 h
    x, h = sample_shape("box", 20_000, "lattice")
    setting = dict(OURS[label])
    voxel = setting.pop("voxel_h") * h
    params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False, **setting)
    v = surface_particles(x, None, params, device="cpu").mesh.vertices.astype(np.float64)
    height = shape_sdf("box")[0](v) / h
    on_face = np.sort(BOX_HALF - np.abs(v), axis=1)[:, 1] > 4 * h  # the second-nearest face is > 4 h away
    assert on_face.sum() > 5000
    assert abs(height[on_face].mean()) < 0.008, f"faces at {height[on_face].mean():+.4f} h"


def test_a_moving_random_sample_gives_every_vertex_its_velocity_with_the_voids_closed():
    # the closing fills sample voids where few particles reach; a vertex there must not read the
    # voxels no particle reaches as velocity 0 (3000 random particles moving at 1 m/s would show
    # 0.68 m/s at some vertices)
    x, h = sample_shape("torus", 3000, "random")
    v = np.tile(np.float32([[0.0, 1.0, 0.0]]), (len(x), 1))
    res = surface_particles(x, v, SurfaceParams(0.5 * h, dense_output=False, close_voids=h), device="cpu")
    assert len(res.mesh.velocities) > 1000
    np.testing.assert_allclose(res.mesh.velocities, np.tile([0.0, 1.0, 0.0], (len(res.mesh.velocities), 1)), atol=1e-5)
