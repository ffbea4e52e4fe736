"""The GPU route of the dense step: COLMAP's patch-match stereo and stereo fusion through pycolmap.

``patch_match_stereo`` needs pycolmap built with CUDA (the PyPI wheels are CPU-only), so this route runs
only where such a build is installed (``pycolmap.has_cuda``). The rest of it runs anywhere: the SfM
model is moved into the site frame (the georeference transform, ``Reconstruction.transform``), the
photos are undistorted into a COLMAP workspace (``undistort_images``), and after patch-match the depth
maps are fused by ``stereo_fusion`` into a coloured cloud with normals, already in the site frame.
The tests run everything but the CUDA call, with a stand-in that writes depth and normal maps in
COLMAP's own format (``write_colmap_array``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def write_colmap_array(path: Path, arr: np.ndarray) -> None:
    """Write a depth (h, w) or normal (h, w, 3) map as COLMAP does: ``width&height&channels&`` then
    float32 values, channel-major, each channel row-major."""
    a = np.asarray(arr, np.float32)
    if a.ndim == 2:
        a = a[..., None]
    h, w, c = a.shape
    with open(path, "wb") as f:
        f.write(f"{w}&{h}&{c}&".encode())
        f.write(np.ascontiguousarray(np.transpose(a, (2, 0, 1))).tobytes())


def read_colmap_array(path: Path) -> np.ndarray:
    """Read a COLMAP depth/normal map (see :func:`write_colmap_array`) -> (h, w) or (h, w, c) float32."""
    raw = Path(path).read_bytes()
    pos, fields = 0, []
    for _ in range(3):
        end = raw.index(b"&", pos)
        fields.append(int(raw[pos:end]))
        pos = end + 1
    w, h, c = fields
    a = np.frombuffer(raw[pos:], np.float32, count=w * h * c).reshape(c, h, w).transpose(1, 2, 0)
    return a[..., 0] if c == 1 else a


def colmap_dense(sfm_dir: Path, scale: float, R: np.ndarray, t: np.ndarray, photos_dir: Path, work: Path, *,
                 max_image_px: int, min_consistent: int, threads: int, log) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Patch-match stereo + fusion on the SfM model mapped into the site frame (x_site = scale * R @ x + t).

    Returns xyz (n, 3), rgb (n, 3) uint8, normals (n, 3) in the site frame, and an info dict.
    """
    import pycolmap

    work = Path(work)
    model = work / "model_site"
    mvs = work / "mvs"
    model.mkdir(parents=True, exist_ok=True)
    rec = pycolmap.Reconstruction(str(sfm_dir))
    rec.transform(pycolmap.Sim3d(float(scale), pycolmap.Rotation3d(np.asarray(R, float)), np.asarray(t, float)))
    rec.write(str(model))
    und = pycolmap.UndistortCameraOptions()
    und.max_image_size = int(max_image_px)
    pycolmap.undistort_images(str(mvs), str(model), str(photos_dir), undistort_options=und,
                              num_threads=int(threads))
    pm = pycolmap.PatchMatchOptions()
    pm.max_image_size = int(max_image_px)
    pm.geom_consistency = True
    log.info("dense: COLMAP patch-match stereo on %d photos (CUDA)", rec.num_reg_images())
    pycolmap.patch_match_stereo(str(mvs), options=pm)
    fo = pycolmap.StereoFusionOptions()
    fo.min_num_pixels = int(min_consistent) + 1  # the pixel itself and the agreeing ones
    fo.max_image_size = int(max_image_px)
    fo.num_threads = int(threads)
    fused_ply = work / "fused.ply"
    pycolmap.stereo_fusion(str(fused_ply), str(mvs), options=fo, output_type="PLY")
    from twinkit.mesh import read_ply

    fused = read_ply(fused_ply)
    xyz = fused.vertices
    nrm = fused.normals.astype(np.float64) if fused.normals is not None else np.zeros_like(xyz)
    rgb = fused.colors if fused.colors is not None else np.full((len(xyz), 3), 128, np.uint8)
    maps = sorted((mvs / "stereo" / "depth_maps").glob("*.geometric.bin"))
    return xyz, rgb, nrm, {"backend": "patchmatch", "depth_maps": len(maps), "fused": int(len(xyz))}
