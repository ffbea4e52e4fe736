"""The sweep table gatherer on a sweep folder laid out like the engine's."""
import json

import numpy as np

from twinkit_segmentation.gather import main as gather_main
from twinkit_segmentation.metrics import majority_labels, scores


def _job(root, n, k, pred, gt, seg):
    job = root / f"job{n}"
    (job / "runs" / "t").mkdir(parents=True)
    (job / "runs" / "t" / "manifest.json").write_text(json.dumps(
        {"overrides": ["recipe=segment_demo", "site=demo", f"segmenter.k_threshold={k}"]}))
    ev = job / "14_evaluate_segmentation"
    ev.mkdir()
    ev.joinpath("seg_metrics.json").write_text(json.dumps(
        {"scores": scores(pred, gt), "upper_bound": scores(majority_labels(seg, gt), gt)}))
    ov = job / "09_oversegment"
    ov.mkdir()
    ov.joinpath("step.json").write_text(json.dumps({"metrics": {"segments": int(seg.max()) + 1}}))


def test_gather_table(tmp_path, capsys):
    gt = np.array([0, 0, 1, 1, 2, 2], np.uint8)
    _job(tmp_path, 0, 0.1, gt.copy(), gt, np.arange(6))
    _job(tmp_path, 1, 1.0, np.array([0, 0, 0, 1, 2, 2], np.uint8), gt, np.array([0, 0, 0, 1, 1, 1]))
    assert gather_main([str(tmp_path)]) == 0
    md = (tmp_path / "sweep_table.md").read_text()
    assert "segmenter.k_threshold=0.1" in md and "segmenter.k_threshold=1.0" in md
    assert "| 100.0 | +0.0 |" in md
    rows = (tmp_path / "sweep_table.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[0].startswith("job,setting,miou")
    assert float(rows[2].split(",")[3]) < 0  # delta against the first job
