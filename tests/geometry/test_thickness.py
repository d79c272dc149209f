import json

import numpy as np
import pytest
import trimesh

from mpmfx.geometry.thickness import Verdict, check_thickness, local_thickness

from .conftest import cube_asset, cube_block, l_bracket, rod, slab, sphere_with_fin

# (shape, true thickness in metres): thin part of each.
SHAPES = {"slab": (slab, 0.1), "rod": (rod, 0.12), "L": (l_bracket, 0.08), "fin": (sphere_with_fin, 0.05)}


def _expected(cells: float) -> Verdict:
    return Verdict.FAIL if cells < 3 else Verdict.WARN if cells < 5 else Verdict.PASS


@pytest.mark.parametrize("name", list(SHAPES))
@pytest.mark.parametrize("grid_n", [16, 40])
def test_thin_part_measured_within_one_cell(domain, name, grid_n):
    make, t = SHAPES[name]
    report = check_thickness(make(t), grid_n=grid_n, name=name, **domain)
    truth = t * grid_n
    assert report.min_thickness_cells == pytest.approx(truth, abs=1.0)
    if abs(truth - 3) > 1 and abs(truth - 5) > 1:  # away from the thresholds
        assert report.verdict is _expected(truth)


@pytest.mark.parametrize("grid_n, verdict", [(20, Verdict.FAIL), (36, Verdict.WARN), (56, Verdict.PASS)])
def test_verdict_flips_with_grid_n(domain, grid_n, verdict):
    # 0.1 m slab: 2, 3.6 and 5.6 cells thick.
    report = check_thickness(slab(0.1), grid_n=grid_n, **domain)
    assert report.verdict is verdict
    if verdict is not Verdict.PASS:
        assert report.min_grid_n_to_pass >= grid_n
        again = check_thickness(slab(0.1), grid_n=report.min_grid_n_to_pass + 2, **domain)
        assert again.verdict is Verdict.PASS


def test_thick_shapes_pass_and_edges_are_not_thin(domain):
    for mesh, t in [
        (trimesh.creation.box(extents=(0.4,) * 3), 0.4),
        (trimesh.creation.icosphere(subdivisions=3, radius=0.3), 0.6),
    ]:
        report = check_thickness(mesh, grid_n=24, **domain)
        assert report.verdict is Verdict.PASS and not report.regions
        assert report.min_thickness_cells == pytest.approx(t * 24, rel=0.25)
        assert report.vertex_thickness_cells.min() >= 5.0


def test_fin_region_is_located_on_the_fin(domain):
    report = check_thickness(sphere_with_fin(0.05), grid_n=32, **domain)
    assert report.verdict is Verdict.FAIL and len(report.regions) == 1
    region = report.regions[0]
    assert region.bbox_min[0] > 0.15 and region.bbox_max[0] == pytest.approx(0.45, abs=0.02)
    # The fin pokes out of the sphere from x ~ 0.19 to 0.45 m.
    assert region.volume == pytest.approx(0.26 * 0.2 * 0.05, rel=0.3)
    on_fin = report.vertex_thickness_cells[np.asarray(sphere_with_fin(0.05).vertices)[:, 0] > 0.25]
    assert np.all(on_fin < 3)
    assert 0 < report.fraction_under < 0.2


def test_feature_thinner_than_raster_is_caught(domain):
    mesh = trimesh.util.concatenate(
        [trimesh.creation.box(extents=(0.3,) * 3), _moved(trimesh.creation.box(extents=(0.2, 0.2, 0.002)), (0.3, 0, 0))]
    )
    report = check_thickness(mesh, grid_n=16, **domain)
    assert report.verdict is Verdict.FAIL
    assert report.regions[0].thickness_cells == 0.0
    assert report.regions[0].bbox_min[0] == pytest.approx(0.2, abs=1e-6)


def _moved(mesh, offset):
    mesh.apply_translation(offset)
    return mesh


def test_local_thickness_of_a_voxel_slab_and_ball():
    inside = np.zeros((30, 30, 30), bool)
    inside[5:25, 5:25, 10:17] = True  # 7 voxels thick
    t = local_thickness(inside, voxel=0.5)
    assert np.all(t[~inside] == 0)
    assert np.median(t[inside]) == pytest.approx(3.5)
    g = np.indices((41, 41, 41)) - 20
    ball = (g**2).sum(0) <= 15**2
    tb = local_thickness(ball, voxel=1.0)
    assert np.median(tb[ball]) == pytest.approx(31, abs=2.0)  # raster: +-1 voxel a side


def test_report_serialises_and_formats(domain):
    report = check_thickness(sphere_with_fin(0.05), grid_n=16, name="finny", **domain)
    data = json.loads(json.dumps(report.to_dict()))
    assert data["verdict"] == "fail" and data["asset"] == "finny"
    assert len(data["regions"]) == len(report.regions)
    table = report.format_table()
    assert "FAIL" in table and "finny" in table and "grid_n to pass" in table


def test_pyvista_ant_legs_are_thin():
    from pyvista import examples

    ant = examples.load_ant().triangulate()
    faces = ant.faces.reshape(-1, 4)[:, 1:]
    mesh = trimesh.Trimesh(np.asarray(ant.points, float), faces)
    size = float(mesh.extents.max()) * 1.1
    origin = mesh.bounds.mean(0) - size / 2
    report = check_thickness(mesh, grid_n=32, origin=origin, size=size, name="ant")
    assert report.verdict is Verdict.FAIL
    # The thinnest parts are the legs: thin vertices lie away from the body's long axis.
    verts = np.asarray(mesh.vertices)
    thin = report.vertex_thickness_cells < report.fail_cells
    assert thin.mean() > 0.1
    body_axis = int(np.argmax(mesh.extents))
    off_axis = [a for a in range(3) if a != body_axis]
    centre = mesh.bounds.mean(0)[off_axis]
    spread = np.abs(verts[:, off_axis] - centre).max(1)
    assert np.median(spread[thin]) > np.median(spread[~thin])


def test_thick_part_reads_within_ten_percent(domain):
    # 12.8 cells: above warn_cells the sweep is coarser, but must stay within 10 %.
    report = check_thickness(trimesh.creation.box(extents=(0.4,) * 3), grid_n=32, **domain)
    assert report.min_thickness_cells == pytest.approx(12.8, rel=0.1)
    assert report.min_grid_n_to_pass == 13  # 0.4 m is 5 cells at grid 12.5


@pytest.mark.parametrize("mesh", [trimesh.creation.box(extents=(0.3,) * 3), rod(0.12)], ids=["box", "rod"])
def test_min_grid_n_to_pass_passes_and_is_near_the_smallest_passing_grid(domain, mesh):
    # It allows for the raster reading faces up to half a voxel out (6 % of these parts
    # at grid 16), so it passes; 10 % below it does not.
    need = check_thickness(mesh, grid_n=16, **domain).min_grid_n_to_pass
    assert check_thickness(mesh, grid_n=need, **domain).verdict is Verdict.PASS
    assert check_thickness(mesh, grid_n=int(need * 0.9), **domain).verdict is not Verdict.PASS


def _max_inscribed_diameter(mesh, lo, hi, rng, n=20000):
    """Independent of the raster: 2 x the largest exact distance to the mesh surface over
    random points inside ``mesh`` and inside the box [lo, hi] (metres)."""
    from trimesh.triangles import closest_point

    from mpmfx.geometry.inside import winding_number

    lo, hi = np.maximum(lo, mesh.bounds[0]), np.minimum(hi, mesh.bounds[1])
    tris = np.asarray(mesh.triangles)
    p = lo + rng.random((n, 3)) * (hi - lo)
    p = p[winding_number(tris, p) > 0.5]
    d = np.full(len(p), np.inf)
    for f in range(len(tris)):
        q = closest_point(np.repeat(tris[f : f + 1], len(p), 0), p)
        d = np.minimum(d, np.linalg.norm(q - p, axis=1))
    return 2.0 * d.max()


def test_pyvista_ant_leg_thickness_matches_the_mesh():
    from pyvista import examples

    ant = examples.load_ant().triangulate()
    mesh = trimesh.Trimesh(np.asarray(ant.points, float), ant.faces.reshape(-1, 4)[:, 1:])
    size = float(mesh.extents.max()) * 1.1
    report = check_thickness(mesh, grid_n=32, origin=mesh.bounds.mean(0) - size / 2, size=size, name="ant")
    dx = report.dx
    # No region for the pinched joints and leg tips (vertices meeting at a point).
    assert all(r.thickness_cells > 0 for r in report.regions)
    legs = [b for b in mesh.split(only_watertight=False) if 80 < len(b.faces) < 100][:2]
    rng = np.random.default_rng(1)
    checked = 0
    for leg in legs:
        for r in report.regions:
            if np.all(r.bbox_min >= leg.bounds[0] - dx) and np.all(r.bbox_max <= leg.bounds[1] + dx):
                truth = _max_inscribed_diameter(leg, r.bbox_min, r.bbox_max, rng) / dx
                # The region reads its median thickness: below the thickest cross-section
                # (the legs taper to their joints) but within a cell of it.
                assert truth - 1.0 < r.thickness_cells <= truth + 0.1
                checked += 1
    assert checked >= 2


def _cube_domain(mesh):
    size = float(mesh.extents.max()) * 1.1
    return {"origin": mesh.bounds.mean(0) - size / 2, "size": size}


@pytest.mark.parametrize("kind", ["union", "kitbash"])
@pytest.mark.parametrize("cells_per_cube", [3, 2])
def test_blocky_asset_reads_its_one_cube_wall(kind, cells_per_cube):
    # Convex corners and edges, internal faces and buried vertices are no thin features:
    # the thinnest part is the one-cube wall, and the grid_n to pass does pass.
    cube = 0.1
    mesh = cube_asset(cube, kind=kind)
    dom = _cube_domain(mesh)
    grid_n = int(round(cells_per_cube * dom["size"] / cube))
    report = check_thickness(mesh, grid_n=grid_n, **dom)
    wall = cube / report.dx
    assert report.min_thickness_cells == pytest.approx(wall, abs=1.0)
    assert all(r.thickness_cells > wall - 1.0 for r in report.regions)
    assert report.verdict is _expected(wall)
    again = check_thickness(mesh, grid_n=report.min_grid_n_to_pass, **dom)
    assert again.verdict is Verdict.PASS, again.format_table()
    assert again.min_grid_n_to_pass <= report.min_grid_n_to_pass + 1


def test_block_of_separate_cubes_is_as_thick_as_the_block():
    # 3 x 3 x 3 cubes of 2 cells each: 6 cells thick, whatever the buried faces.
    mesh = cube_block(0.1)
    dom = _cube_domain(mesh)
    report = check_thickness(mesh, grid_n=int(round(2 * dom["size"] / 0.1)), **dom)
    assert report.verdict is Verdict.PASS and not report.regions, report.format_table()
    assert report.min_thickness_cells == pytest.approx(6.0, rel=0.1)


@pytest.mark.parametrize("extents", [(0.3, 0.4, 0.5), (0.27, 0.33, 0.41), (0.5, 0.19, 0.36)])
def test_convex_edges_and_corners_of_a_box_are_no_feature(extents):
    # Wherever the box's faces fall between raster samples, the outermost voxels along its
    # edges and at its corners (depth ~0, tiny inscribed balls) are no thin region.
    mesh = trimesh.creation.box(extents=extents)
    dom = _cube_domain(mesh)
    report = check_thickness(mesh, grid_n=48, **dom)
    assert report.verdict is Verdict.PASS and not report.regions, report.format_table()


@pytest.mark.parametrize("fin_t", [0.002, 0.006], ids=["thinner-than-raster", "measured"])
def test_grid_n_to_pass_is_stable_under_a_sliver_of_negligible_volume(domain, fin_t):
    # A sliver (an ear tip) once set "grid_n to pass" for the whole object: from 13 to ~640.
    box = trimesh.creation.box(extents=(0.4,) * 3)
    fin = _moved(trimesh.creation.box(extents=(0.06, 0.06, fin_t)), (0.0, 0.225, 0.0))  # 5 mm into the box
    alone = check_thickness(box, grid_n=32, **domain)
    report = check_thickness(trimesh.util.concatenate([box, fin]), grid_n=32, **domain)
    assert report.min_grid_n_to_pass <= alone.min_grid_n_to_pass * 1.1, report.format_table()
    assert report.verdict is Verdict.PASS
    (sliver,) = report.regions
    assert sliver.ignored and sliver.bbox_min[1] > 0.19
    assert 0 < report.fraction_ignored < 0.01 and report.fraction_thin >= report.fraction_ignored
    assert "ignored" in report.format_table() and report.to_dict()["regions"][0]["ignored"]
    # a fin of real volume still counts
    big = _moved(trimesh.creation.box(extents=(0.3, 0.3, fin_t)), (0.0, 0.345, 0.0))
    assert check_thickness(trimesh.util.concatenate([box, big]), grid_n=32, **domain).verdict is Verdict.FAIL
