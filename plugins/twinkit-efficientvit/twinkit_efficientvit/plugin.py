"""twinkit entry point: registers the 2D image models of this package.

Importing this module imports no heavy library; torch, transformers and
ai-edge-litert are imported when a model is built.
"""
from __future__ import annotations

from twinkit import hookimpl

from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit
from twinkit_efficientvit.hf import HFParams, build_hf
from twinkit_efficientvit.tflite import DeepLabTFLiteParams, build_deeplab_tflite


@hookimpl
def twinkit_register_image_models(register):
    register("efficientvit_b0", build_efficientvit, params=EfficientViTParams,
             description="EfficientViT-Seg-B0, CityScapes 19 classes (default; 0.7 M parameters, PyTorch)")
    register("hf_segformer", build_hf, params=HFParams,
             description="Hugging Face SegFormer / Mask2Former by model id or folder, labels mapped to CityScapes")
    register("deeplab_edgetpu_tflite", build_deeplab_tflite, params=DeepLabTFLiteParams,
             description="EdgeTPU-DeepLab-slim CityScapes, int8 TFLite 513x513 (needs ai-edge-litert)")
