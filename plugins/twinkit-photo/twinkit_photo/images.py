"""Photo folders: listing, validation and EXIF (GPS, focal length)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from twinkit import InputError

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".tif", ".tiff"}


@dataclass
class PhotoInfo:
    name: str
    width: int
    height: int
    lat: float | None = None
    lon: float | None = None
    alt: float | None = None
    focal_35mm: float | None = None
    make: str | None = None
    model: str | None = None
    focal_mm: float | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def camera_key(self) -> tuple:
        """Photos with the same key can share one set of intrinsics: image size, EXIF make, model, focal."""
        focal = self.focal_mm if self.focal_mm else self.focal_35mm
        return (self.width, self.height, self.make or "", self.model or "", round(focal, 1) if focal else None)

    @property
    def has_gps(self) -> bool:
        return self.lat is not None and self.lon is not None


def list_images(folder: Path) -> list[Path]:
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder of photos; set site.inputs.photos to a folder of JPG/PNG files")
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        from twinkit import artefacts as A

        raise InputError(f"{folder}: no photos (.jpg, .jpeg, .png, .tif) in this folder; "
                         + (A.why_no_photos(folder) or "point site.inputs.photos at the folder that holds them"))
    return files


def drop_identical(files: list[Path], log=None) -> list[Path]:
    """``files`` without the byte-identical copies (same size and SHA-256) of an earlier one, each dropped one
    named with the one it repeats in a warning: a copy adds no view, and two images at one pose would make
    structure from motion match a photo with itself (docs/photo.md)."""
    import hashlib

    by_size: dict[int, list[Path]] = {}
    for f in files:
        by_size.setdefault(f.stat().st_size, []).append(f)
    seen: dict[str, Path] = {}
    dropped: set[Path] = set()
    for group in (g for g in by_size.values() if len(g) > 1):
        for f in group:
            h = hashlib.sha256(f.read_bytes()).hexdigest()
            if h in seen:
                dropped.add(f)
                if log is not None:
                    log.warning("%s: byte-identical to %s, dropped (a copy adds no view; remove it from the "
                                "photo folder)", f.name, seen[h].name)
            else:
                seen[h] = f
    return [f for f in files if f not in dropped]


def _rational(v) -> float:
    if isinstance(v, tuple) and len(v) == 2:
        return float(v[0]) / float(v[1]) if v[1] else 0.0
    return float(v)


def _dms(v) -> float:
    d, m, s = (_rational(x) for x in v)
    return d + m / 60.0 + s / 3600.0


def read_info(path: Path) -> PhotoInfo:
    """Open the image fully (a truncated or corrupt file fails here) and read its EXIF."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    try:
        with Image.open(path) as im:
            im.load()
            w, h = im.size
            exif_bytes = im.info.get("exif")
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise InputError(f"{path}: not a readable image ({type(exc).__name__}: {exc}); "
                         f"re-export or remove this file from the photo folder") from None
    info = PhotoInfo(path.name, int(w), int(h))
    if not exif_bytes:
        info.notes.append("no EXIF")
        return info
    try:
        import piexif

        ex = piexif.load(exif_bytes)
    except Exception as exc:  # noqa: BLE001 - broken EXIF is a note, not a failure
        info.notes.append(f"unreadable EXIF ({exc})")
        return info
    gps = ex.get("GPS") or {}
    try:
        if 2 in gps and 4 in gps:
            lat, lon = _dms(gps[2]), _dms(gps[4])
            if gps.get(1, b"N") in (b"S", "S"):
                lat = -lat
            if gps.get(3, b"E") in (b"W", "W"):
                lon = -lon
            if abs(lat) > 1e-9 or abs(lon) > 1e-9:
                info.lat, info.lon = lat, lon
            if 6 in gps:
                alt = _rational(gps[6])
                if gps.get(5, 0) in (1, b"\x01"):
                    alt = -alt
                info.alt = alt
    except (TypeError, ValueError, ZeroDivisionError) as exc:
        info.notes.append(f"bad GPS tags ({exc})")
    f35 = (ex.get("Exif") or {}).get(41989)  # FocalLengthIn35mmFilm
    if f35:
        info.focal_35mm = float(f35)
    zeroth = ex.get("0th") or {}
    for tag, attr in ((271, "make"), (272, "model")):  # Make, Model
        v = zeroth.get(tag)
        if isinstance(v, bytes):
            v = v.decode("utf-8", "replace")
        if v and str(v).strip("\x00 "):
            setattr(info, attr, str(v).strip("\x00 "))
    try:
        f = (ex.get("Exif") or {}).get(37386)  # FocalLength (mm)
        if f:
            info.focal_mm = _rational(f) or None
    except (TypeError, ValueError, ZeroDivisionError):
        pass
    return info


def camera_groups(infos: list[PhotoInfo]) -> list[dict]:
    """Photos grouped by what makes their intrinsics differ: image size (portrait and landscape shots of one
    phone are two groups), EXIF make and model, and focal length (a zoom). In file-name order of each group's
    first photo; each ``{"size": [w, h], "make", "model", "focal_mm", "photos": [names]}``."""
    groups: dict[tuple, dict] = {}
    for i in infos:
        g = groups.setdefault(i.camera_key, {"size": [i.width, i.height], "make": i.make, "model": i.model,
                                             "focal_mm": i.focal_mm or i.focal_35mm, "photos": []})
        g["photos"].append(i.name)
    return list(groups.values())


def focal_px_from_35mm(info: PhotoInfo) -> float | None:
    """Focal length in pixels from the 35 mm equivalent (36 mm wide frame, long side)."""
    if not info.focal_35mm:
        return None
    return info.focal_35mm / 36.0 * max(info.width, info.height)


def read_k_txt(folder: Path) -> list[list[float]] | None:
    """A ``K.txt`` (3x3 intrinsics, as shipped with openMVG sample sets) beside the photos, if any."""
    p = Path(folder) / "K.txt"
    if not p.exists():
        return None
    try:
        vals = [float(v) for v in p.read_text().split()]
    except ValueError:
        raise InputError(f"{p}: expected 9 numbers (a 3x3 intrinsics matrix); fix or remove the file") from None
    if len(vals) != 9:
        raise InputError(f"{p}: expected 9 numbers (a 3x3 intrinsics matrix), found {len(vals)}")
    return [vals[0:3], vals[3:6], vals[6:9]]
