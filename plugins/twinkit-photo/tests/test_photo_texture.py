"""Texture from the photos: a plane with a known pattern, photographed by two cameras, one view partly
blocked by a box; the projected texture reproduces the pattern, also behind the box, and keeps the base
colour where no photo sees the surface."""
from __future__ import annotations

import numpy as np

from twinkit_photo.projtex import PhotoView, project_texture

W, H, F = 320, 240, 260.0
K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])


def pattern(x, y):
    """Ground truth colour at (x, y) on the plane z = 0: a coloured 0.5 m checker."""
    a = (np.floor(x / 0.5) + np.floor(y / 0.5)) % 2
    return np.stack([40 + 180 * a, 200 - 120 * a, 90 + 0 * a], -1).astype(np.float32)


def plane(n=40, half=4.0):
    g = np.linspace(-half, half, n + 1)
    X, Y = np.meshgrid(g, g)
    v = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    idx = np.arange(v.shape[0]).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    f = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    uv = (v[:, :2] + half) / (2 * half) * 0.98 + 0.01  # planar UVs (v up), inside [0, 1]
    return v, f, uv[f]


def box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                  [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return c, f


def look_at(C, target):
    f = np.asarray(target, float) - C
    f /= np.linalg.norm(f)
    r = np.cross(f, [0, 0, 1.0])
    r /= np.linalg.norm(r)
    return np.stack([r, np.cross(f, r), f], 1)  # columns: camera x, y (down), z (forward) in the world


def render(C, R, occluder):
    """Photo of the checker plane with a uniform magenta box in front (ray casting, pixel centres)."""
    import open3d as o3d

    u, v = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    d = np.c_[(u.ravel() - W / 2) / F, (v.ravel() - H / 2) / F, np.ones(u.size)] @ R.T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    img = np.full((H * W, 3), 255, np.float32)
    t_plane = np.where(d[:, 2] < -1e-6, -C[2] / np.minimum(d[:, 2], -1e-6), np.inf)
    hit = C + d * t_plane[:, None]
    on = np.isfinite(t_plane) & (np.abs(hit[:, 0]) < 4) & (np.abs(hit[:, 1]) < 4)
    img[on] = pattern(hit[on, 0], hit[on, 1])
    bv, bf = occluder
    sc = o3d.t.geometry.RaycastingScene()
    sc.add_triangles(o3d.core.Tensor(bv.astype(np.float32)), o3d.core.Tensor(bf.astype(np.uint32)))
    rays = np.c_[np.broadcast_to(C, d.shape), d].astype(np.float32)
    tb = sc.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    img[tb < t_plane] = [255, 0, 255]
    return img.reshape(H, W, 3).astype(np.uint8)


def test_projected_texture_reproduces_the_pattern_and_respects_occlusion():
    pv, pf, puv = plane()
    bv, bf = box([-0.6, -0.6, 0.0], [0.6, 0.6, 1.2])  # a box standing on the plane
    verts = np.r_[pv, bv]
    faces = np.r_[pf, bf + len(pv)]
    uv = np.r_[puv, np.full((len(bf), 3, 2), 0.005)]  # the box's faces map to one corner texel
    size = 256
    base = np.full((size, size, 3), 7, np.uint8)
    views = []
    for C in (np.array([0.0, -6.0, 4.0]), np.array([0.0, 6.0, 4.0])):
        R = look_at(C, [0, 0, 0])
        views.append(PhotoView(f"c{len(views)}.jpg", K, R, C, render(C, R, (bv, bf))))
    tex, info = project_texture(verts, faces, uv, base, views, max_views=2, threads=1)
    assert info["texels_from_photos_ratio"] > 0.5
    # texel centres -> plane positions (the planar UV mapping inverted)
    rows, cols = np.mgrid[0:size, 0:size]
    s = (cols + 0.5) / size
    t = 1.0 - (rows + 0.5) / size
    x = (s - 0.01) / 0.98 * 8 - 4
    y = (t - 0.01) / 0.98 * 8 - 4
    inside = (np.abs(x) < 3.9) & (np.abs(y) < 3.9)
    got = (tex != 7).any(-1) & inside
    truth = pattern(x, y)
    # away from checker edges (where bilinear sampling blends two squares)
    fx, fy = np.abs(((x / 0.5) % 1) - 0.5), np.abs(((y / 0.5) % 1) - 0.5)
    clear = got & (fx < 0.35) & (fy < 0.35)
    err = np.abs(tex[clear].astype(np.float32) - truth[clear]).mean()
    assert clear.sum() > 5000 and err < 6.0
    # no magenta leaked onto the plane: texels behind the box (for one camera) came from the other one
    magenta = (tex[..., 0] > 200) & (tex[..., 1] < 60) & (tex[..., 2] > 200)
    assert not (magenta & inside & ((np.abs(x) > 0.7) | (np.abs(y) > 0.7))).any()
    behind = got & (np.abs(x) < 0.5) & (np.abs(y) > 0.8) & (np.abs(y) < 2.0) & (fx < 0.35) & (fy < 0.35)
    assert behind.sum() > 100
    assert np.abs(tex[behind].astype(np.float32) - truth[behind]).mean() < 8.0
    # under the box no photo sees the plane: the base colour stays
    under = inside & (np.abs(x) < 0.45) & (np.abs(y) < 0.45)
    assert (tex[under] == 7).all()


def test_a_view_with_an_occluder_the_mesh_lacks_is_left_out_by_the_photo_consistency_check():
    """A box floats between one photo and the plane (a tree or a walker the mesh does not have): that photo is
    the closest, so the best, for the plane behind the box, and without the check paints the box onto it. Three
    other photos see the plane there; their consensus leaves the odd one out."""
    pv, pf, puv = plane()
    occluder = box([-0.4, -4.9, 2.3], [0.4, -4.1, 3.0])  # in front of camera 0 only, not in the mesh
    size = 256
    base = np.full((size, size, 3), 7, np.uint8)
    views = []
    for C in (np.array([0.0, -6.0, 4.0]), np.array([0.0, 6.0, 4.0]), np.array([-6.0, 0.0, 4.0]),
              np.array([6.0, 0.0, 4.0])):
        R = look_at(C, [0, 0, 0])
        views.append(PhotoView(f"c{len(views)}.jpg", K, R, C, render(C, R, occluder)))
    rows, cols = np.mgrid[0:size, 0:size]
    x = ((cols + 0.5) / size - 0.01) / 0.98 * 8 - 4
    y = ((1.0 - (rows + 0.5) / size) - 0.01) / 0.98 * 8 - 4
    inside = (np.abs(x) < 3.9) & (np.abs(y) < 3.9)
    truth = pattern(x, y)
    fx, fy = np.abs(((x / 0.5) % 1) - 0.5), np.abs(((y / 0.5) % 1) - 0.5)
    clear = inside & (fx < 0.35) & (fy < 0.35)
    shadow = clear & (np.hypot(x, y + 1.5) < 0.5)  # the plane camera 0 sees only through the box

    def magenta(tex):
        t = tex.astype(np.float32)
        return (t[..., 1] < 0.5 * np.minimum(t[..., 0], t[..., 2])) & (t[..., 2] > 120)  # green well below both

    old, info_old = project_texture(pv, pf, puv, base, views, max_views=2, consistency_views=0, threads=1)
    assert (magenta(old) & shadow).sum() > 0.3 * shadow.sum()  # the scene does show the failure
    tex, info = project_texture(pv, pf, puv, base, views, max_views=2, consistency_views=8, consistency_levels=45,
                                threads=1)
    assert info["views_rejected_inconsistent"] > 0 and info_old["views_rejected_inconsistent"] == 0
    # gone where the other photos see the plane about as well as camera 0 (measured: none left); nearer
    # camera 0 (y < -2 m) its score outweighs them for some faces (a close photo counts more than far ones)
    assert (magenta(tex) & shadow).sum() < 0.02 * shadow.sum()
    assert (magenta(tex) & inside).sum() < 0.3 * (magenta(old) & inside).sum()  # measured 0.19
    assert np.abs(tex[shadow].astype(np.float32) - truth[shadow]).mean() < 10.0
    # elsewhere the check changes nothing that matters: the pattern is as good as before
    rest = clear & (np.hypot(x, y + 1.5) > 1.5)
    assert np.abs(tex[rest].astype(np.float32) - truth[rest]).mean() < 6.0


def test_photo_texture_step_refuses_a_mesh_without_uvs(tmp_path):
    import json

    import pytest
    from twinkit import InputError
    from twinkit.mesh import Mesh, write_ply
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_photo.plugin as photo

    pv, pf, _ = plane(4)
    src = tmp_path / "in"
    src.mkdir()
    write_ply(src / "textured_mesh.ply", Mesh(vertices=pv, faces=pf))
    (src / "cameras_site.json").write_text(json.dumps({"cameras": []}))
    with pytest.raises(InputError, match="textured_mesh.ply.*texture coordinates"):
        run_step(plugin_from_module(photo, "step", "photo_texture"), tmp_path / "run",
                 {"in_textured_mesh_ply": src / "textured_mesh.ply", "in_photos_dir": src,
                  "in_cameras_site_json": src / "cameras_site.json"})


def test_the_default_blend_averages_the_consistent_photos_and_lands_nearer_the_truth_than_the_best_photo():
    """Six photos of the plane, each with its own sensor noise and exposure (gain 0.9-1.1): the step's defaults
    average the photos that pass the consistency check, so the texture is nearer the true pattern than the
    best-scored photo alone would make it (the demo's texture bench and the held-out photos of Sceaux and Lund
    agree: docs/photo.md "Blending")."""
    from twinkit_photo.plugin import PhotoTextureParams

    pv, pf, puv = plane()
    size = 256
    base = np.full((size, size, 3), 7, np.uint8)
    rng = np.random.default_rng(3)
    no_box = box([9.0, 9.0, 9.0], [9.1, 9.1, 9.1])  # far outside every view
    views = []
    for k, a in enumerate(np.radians([0, 60, 120, 180, 240, 300])):
        r = 5.0 + 0.8 * k  # the photos' scores differ: the closest one is the best
        C = np.array([r * np.cos(a), r * np.sin(a), 4.0])
        R = look_at(C, [0, 0, 0])
        img = render(C, R, no_box).astype(np.float32) * rng.uniform(0.9, 1.1)
        img += rng.normal(0.0, 14.0, img.shape)
        views.append(PhotoView(f"c{k}.jpg", K, R, C, np.clip(np.rint(img), 0, 255).astype(np.uint8)))
    rows, cols = np.mgrid[0:size, 0:size]
    x = ((cols + 0.5) / size - 0.01) / 0.98 * 8 - 4
    y = ((1.0 - (rows + 0.5) / size) - 0.01) / 0.98 * 8 - 4
    fx, fy = np.abs(((x / 0.5) % 1) - 0.5), np.abs(((y / 0.5) % 1) - 0.5)
    clear = (np.abs(x) < 3.0) & (np.abs(y) < 3.0) & (fx < 0.3) & (fy < 0.3)
    truth = pattern(x, y)
    p = PhotoTextureParams()
    kw = dict(consistency_views=p.consistency_views, consistency_levels=p.consistency_levels, threads=1)
    tex, _ = project_texture(pv, pf, puv, base, views, max_views=p.max_views, sharpness=p.sharpness, **kw)
    best, _ = project_texture(pv, pf, puv, base, views, max_views=1, **kw)
    err = np.abs(tex[clear].astype(np.float32) - truth[clear]).mean()
    err_best = np.abs(best[clear].astype(np.float32) - truth[clear]).mean()
    assert clear.sum() > 5000
    old, _ = project_texture(pv, pf, puv, base, views, max_views=3, sharpness=4.0, **kw)  # the defaults before
    err_old = np.abs(old[clear].astype(np.float32) - truth[clear]).mean()
    assert err < 0.7 * err_best and err < 0.8 * err_old, (err, err_old, err_best)
