"""How the code base holds its concepts (issue 43's measures): files and functions past their size limits in
production code, cross-plugin imports, and the places that re-implement a street concept the core owns.

Production code is twinkit/ and plugins/*/<package>/ (not tests, benchmarks or examples). The concept rows are
found by pattern (a definition's name or a library call), so they count candidates to look at, not proofs;
the file list under each row says where.

Run: .venv/bin/python bench/bench_structure.py   (part of `make bench`; takes about a second)
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 80

#: concept -> (what the core's one place is, regular expression for a re-implementation elsewhere)
CONCEPTS: dict[str, tuple[str, str]] = {
    "OpenDRIVE lanes walked through carla.Map": ("twinkit/street/lanes.py", r"carla\.Map\("),
    "local ground models": ("twinkit/street/ground.py",
                            r"^\s*(class GroundGrid\b|def ground_grid\b|def height_above_ground\b|def _window_level\b"
                            r"|class LocalGround\b|def local_ground\w*\b)"),
    "CityScapes id tables": ("twinkit/cityscapes.py",
                             r"^(ROAD|SIDEWALK|BUILDING|WALL|FENCE|POLE|VEGETATION|TERRAIN|CAR|PERSON|SKY)"
                             r"(_ID)? *= *\d+\b"),
    "mesh containers": ("twinkit/mesh/core.py", r"^class \w*Mesh\b"),
    "OBJ writers": ("twinkit/mesh/obj.py", r"""["']mtllib """),
    "similarity fits": ("twinkit/geo/similarity.py", r"^def (umeyama|fit_similarity\w*)\b"),
    "hole closers (ear clipping, fans)": ("twinkit/street/holes.py", r"^\s*def \w*(ear_?clip|fan_fill|earcut)\w*\("),
}


def production_files() -> list[Path]:
    files = sorted((ROOT / "twinkit").rglob("*.py"))
    for pkg in sorted(ROOT.glob("plugins/*/twinkit_*")):
        files += sorted(pkg.rglob("*.py"))
    return [f for f in files if "tests" not in f.parts]


def long_functions(path: Path) -> list[tuple[str, int]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = (node.end_lineno or node.lineno) - node.lineno + 1
            if n > MAX_FUNCTION_LINES:
                out.append((node.name, n))
    return out


def concept_sites(files: list[Path]) -> dict[str, list[str]]:
    sites: dict[str, list[str]] = {}
    for concept, (home, pattern) in CONCEPTS.items():
        rx = re.compile(pattern, re.M)
        hits = []
        for f in files:
            rel = f.relative_to(ROOT).as_posix()
            n = len(rx.findall(f.read_text(encoding="utf-8")))
            if n and rel != home:
                hits.append(f"{rel} ({n})")
        sites[concept] = hits
    return sites


def cross_plugin_imports() -> int:
    sys.path.insert(0, str(ROOT / "tests"))
    try:
        from test_architecture import cross_imports
    except Exception:  # the architecture test moved: report unknown rather than 0
        return -1
    return len(cross_imports(ROOT))


def main() -> int:
    files = production_files()
    big = [(f, len(f.read_text(encoding="utf-8").splitlines())) for f in files]
    big = sorted([(f, n) for f, n in big if n > MAX_FILE_LINES], key=lambda t: -t[1])
    longf = [(f, name, n) for f in files for name, n in long_functions(f)]
    print("| measure | value |\n|---|---:|")
    print(f"| production files | {len(files)} |")
    print(f"| files over {MAX_FILE_LINES} lines | {len(big)} |")
    print(f"| files over 950 lines | {sum(1 for _, n in big if n > 950)} |")
    print(f"| functions over {MAX_FUNCTION_LINES} lines | {len(longf)} |")
    print(f"| cross-plugin imports | {cross_plugin_imports()} |")
    sites = concept_sites(files)
    for concept, hits in sites.items():
        print(f"| {concept}: places besides the core's one | {len(hits)} |")
    print("\nFiles over the limit: " + (", ".join(f"{f.relative_to(ROOT).as_posix()} ({n})" for f, n in big) or "none"))
    print("\nFunctions over the limit:")
    for f, name, n in sorted(longf, key=lambda t: -t[2]):
        print(f"- {f.relative_to(ROOT).as_posix()}: {name} ({n} lines)")
    print("\nConcept re-implementations found by pattern:")
    for concept, hits in sites.items():
        print(f"- {concept}: " + (", ".join(hits) or "none"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
