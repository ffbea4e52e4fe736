"""twinkit-efficientvit: 2D CityScapes image models for twinkit.

Image models (component kind ``image_model``):

- ``efficientvit_b0``: EfficientViT-Seg-B0 (this package's own PyTorch code, official weights);
- ``hf_segformer``: Hugging Face transformers SegFormer / Mask2Former (optional extra ``hf``);
- ``deeplab_edgetpu_tflite``: EdgeTPU-DeepLab-slim int8 TFLite (optional extra ``tflite``).

Importing this package imports numpy only.
"""
from twinkit_efficientvit.common import CITYSCAPES_CLASSES

__version__ = "0.1.0"
__all__ = ["CITYSCAPES_CLASSES", "__version__"]
