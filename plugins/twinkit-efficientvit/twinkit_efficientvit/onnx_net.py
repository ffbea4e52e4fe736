"""EfficientViT-Seg-B0's network exported to ONNX and run by OpenVINO (``runtime=openvino``, the default on CPU when
installed) or ONNX Runtime (``runtime=onnxruntime``, the default when OpenVINO is not).

The ONNX file is exported from this package's torch model at first use (torch's TorchScript exporter,
batch, height and width dynamic) into the download cache (``$XDG_CACHE_HOME/twinkit/models``, by default
``~/.cache/twinkit/models``); a file of the same name beside the weights is used first, but nothing is ever
written there (a shared models folder stays as it is). Its name carries a hash of what it is made of
(:func:`export_key`: the weights' sha256, ``model.py``, the export settings, the torch version), so a
changed model or checkpoint exports again; it is written to a temporary name and moved into place, so
runs exporting at the same time never read half a file.

Each session is checked once against the torch network on a small fixed image (:func:`check_against`):
a file that does not reproduce the torch logits is exported again, and if the fresh export fails the
check too the model runs on torch (with a warning). The labels of the runtimes agree on real
images to well under 0.1 % of pixels (docs/image-models.md "Runtimes").

OpenVINO compiles the file for the CPU in float32 (``INFERENCE_PRECISION_HINT``): on a CPU with bfloat16 units
(AMX, AVX-512 BF16) its default is bfloat16, which moved 17 % of the labels of a noise image.
"""
from __future__ import annotations

import hashlib
import importlib.util
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

#: ONNX operator set of the export
OPSET = 17
#: bump when the export itself changes (names, dynamic axes): the cached files then no longer match
EXPORT_VERSION = 1
#: largest |logit difference| torch vs ONNX Runtime accepted by :func:`check_against` (measured: 3e-4)
CHECK_ATOL = 5e-3


#: what runs an exported file (each is also the module it needs, beside ``onnx`` for torch's exporter)
BACKENDS = ("openvino", "onnxruntime")


def available(backend: str = "onnxruntime") -> bool:
    """Whether ``backend`` (openvino or onnxruntime) and the ONNX package (which torch's exporter needs) are installed."""
    return backend in BACKENDS and all(importlib.util.find_spec(m) is not None for m in (backend, "onnx"))


def export_key(weights_sha256: str, fused: bool) -> str:
    """16 hex digits naming one export: weights, model code, export settings, torch version."""
    import torch

    h = hashlib.sha256()
    h.update(Path(__file__).with_name("model.py").read_bytes())
    h.update(f"{weights_sha256}|fused={fused}|opset={OPSET}|v{EXPORT_VERSION}|torch={torch.__version__}".encode())
    return h.hexdigest()[:16]


def cache_folders(weights_path: Path) -> list[Path]:
    """Where an exported file is looked for, in order: beside the weights, the download cache (written)."""
    from twinkit_efficientvit.weights import cache_dir

    out = [Path(weights_path).resolve().parent]
    if cache_dir() not in out:
        out.append(cache_dir())
    return out


def export(net, path: Path) -> None:
    """Write ``net`` (eval mode, float32, NCHW input) as ONNX to ``path`` (atomically)."""
    import warnings

    import torch

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".part")
    os.close(fd)
    try:
        with warnings.catch_warnings(), torch.inference_mode():
            warnings.simplefilter("ignore")  # the exporter's deprecation and tracer notes
            torch.onnx.export(net, (torch.zeros(1, 3, 64, 128),), tmp, dynamo=False, opset_version=OPSET,
                              input_names=["image"], output_names=["logits"],
                              dynamic_axes={"image": {0: "b", 2: "h", 3: "w"}, "logits": {0: "b", 2: "h8", 3: "w8"}})
        os.chmod(tmp, 0o644)  # mkstemp's 0600 would keep the cache from other users
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


class Session:
    """An exported file compiled by ``backend`` for the CPU with ``threads`` threads (0: one per core):
    ``session.run(x) -> logits`` (numpy float32).

    ONNX Runtime runs without spin-waiting (on a shared machine a spinning pool burns the cores other work
    needs: measured 2x the CPU time under load); OpenVINO in float32, tuned for one image at a time."""

    def __init__(self, path: Path, threads: int, backend: str = "onnxruntime"):
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r} (one of {', '.join(BACKENDS)})")
        self.backend, threads = backend, max(0, int(threads))
        if backend == "openvino":
            import openvino as ov

            config = {"INFERENCE_PRECISION_HINT": "f32", "PERFORMANCE_HINT": "LATENCY"}
            if threads:
                config["INFERENCE_NUM_THREADS"] = threads
            core = ov.Core()
            self._request = core.compile_model(core.read_model(str(path)), "CPU", config).create_infer_request()
            return
        import onnxruntime as ort

        so = ort.SessionOptions()
        so.intra_op_num_threads = threads
        so.inter_op_num_threads = 1
        so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        so.add_session_config_entry("session.intra_op.allow_spinning", "0")
        so.log_severity_level = 3
        self._sess = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])

    def run(self, x: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float32)
        if self.backend == "openvino":
            return np.array(self._request.infer({0: x})[0], dtype=np.float32, copy=True)
        return self._sess.run(None, {"image": x})[0]


def check_against(net, sess: Session) -> float:
    """Largest |logit difference| of ``sess`` and the torch ``net`` on a fixed 96x160 image (normalised noise)."""
    import torch

    x = torch.randn(1, 3, 96, 160, generator=torch.Generator().manual_seed(0))
    with torch.inference_mode():
        ref = net(x.contiguous(memory_format=torch.channels_last)).float().numpy()
    got = sess.run(x.numpy())
    return float(np.abs(ref - got).max()) if got.shape == ref.shape else float("inf")


class OnnxNet:
    """The torch network ``net`` exported once and run by ``backend`` (openvino or onnxruntime):
    ``net_onnx(x) -> logits`` (numpy)."""

    def __init__(self, net, weights_path: Path, weights_sha256: str, fused: bool, threads: int,
                 backend: str = "onnxruntime"):
        self.threads, self.backend = max(0, int(threads)), backend
        name = f"{Path(weights_path).stem}.{export_key(weights_sha256, fused)}.onnx"
        folders = cache_folders(Path(weights_path))
        found = next((d / name for d in folders if (d / name).is_file()), None)
        self.sess, self.path = None, found
        if found is not None:
            self.sess = self._checked(net, found)
        if self.sess is None:
            from twinkit_efficientvit.weights import cache_dir

            self.path = cache_dir() / name
            export(net, self.path)
            log.info("exported the network to %s", self.path)
            self.sess = self._checked(net, self.path)
        if self.sess is None:
            raise RuntimeError(f"the ONNX export {self.path} does not reproduce the torch network's logits")

    def _checked(self, net, path: Path):
        try:
            sess = Session(path, self.threads, self.backend)
        except Exception as exc:  # a damaged or foreign file: export again
            log.warning("could not load %s (%s); exporting again", path, str(exc)[:200])
            return None
        err = check_against(net, sess)
        if err > CHECK_ATOL:
            log.warning("%s differs from the torch network by %.2g (over %.0g); exporting again", path, err, CHECK_ATOL)
            return None
        return sess

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """``x (b, 3, h, w)`` float32 normalised -> logits ``(b, 19, h/8, w/8)`` float32."""
        return self.sess.run(x)
