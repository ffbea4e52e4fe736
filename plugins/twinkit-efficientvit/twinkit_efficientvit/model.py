"""EfficientViT-Seg-B0 (CityScapes) written for twinkit from the published architecture.

Reference: Cai, Li, Hu, Gan, Han, "EfficientViT: Multi-Scale Linear Attention for
High-Resolution Dense Prediction", ICCV 2023. The module *names* follow the
official checkpoint's state-dict keys (``backbone.input_stem.op_list.0.conv.weight``
and so on, listed in ``../shared/models/efficientvit_seg_b0_cityscapes.keys.tsv``)
so ``load_state_dict(strict=True)`` accepts the released weights; the code itself
is this project's.

Shapes in this module: images are ``(b, 3, h, w)`` float32, RGB normalised with
ImageNet mean/std, ``h`` and ``w`` multiples of 32; :class:`EfficientViTSeg`
returns logits ``(b, 19, h/8, w/8)`` float32 (CityScapes trainIds).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

BN_EPS = 1e-5
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


class ConvBNAct(nn.Module):
    """Conv2d, optional BatchNorm (``norm``), optional hard-swish. Keys: ``conv.*``, ``norm.*``."""

    def __init__(self, cin: int, cout: int, kernel: int = 1, stride: int = 1, groups: int = 1,
                 bias: bool = False, norm: bool = True, act: bool = True):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, kernel, stride=stride, padding=kernel // 2, groups=groups, bias=bias)
        self.norm = nn.BatchNorm2d(cout, eps=BN_EPS) if norm else None
        self.act = nn.Hardswish() if act else None

    @torch.no_grad()
    def fuse_norm(self) -> None:
        """Fold the (eval-mode) BatchNorm into the conv's weight and bias; drops ``norm``."""
        if self.norm is None:
            return
        bn = self.norm
        scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)
        bias = self.conv.bias if self.conv.bias is not None else torch.zeros_like(bn.running_mean)
        self.conv.weight.mul_(scale.view(-1, 1, 1, 1))
        self.conv.bias = nn.Parameter((bias - bn.running_mean) * scale + bn.bias)
        self.norm = None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.conv(x)
        if self.norm is not None:
            x = self.norm(x)
        if self.act is not None:
            x = self.act(x)
        return x


class Sequence(nn.Module):
    """A list of layers applied in order; keys ``op_list.<i>.*`` (parameter-free layers included)."""

    def __init__(self, layers: list[nn.Module]):
        super().__init__()
        self.op_list = nn.ModuleList(layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.op_list:
            x = layer(x)
        return x


class Residual(nn.Module):
    """``main(x) + x`` (or just ``main(x)`` without shortcut). Keys: ``main.*``."""

    def __init__(self, main: nn.Module, shortcut: bool):
        super().__init__()
        self.main = main
        self.shortcut = shortcut

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.main(x)
        return y + x if self.shortcut else y


class DepthwiseSeparable(nn.Module):
    """Depthwise 3x3 + BN + act, pointwise 1x1 + BN (stem block)."""

    def __init__(self, cin: int, cout: int):
        super().__init__()
        self.depth_conv = ConvBNAct(cin, cin, 3, groups=cin)
        self.point_conv = ConvBNAct(cin, cout, 1, act=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.point_conv(self.depth_conv(x))


class MBConv(nn.Module):
    """Inverted residual: 1x1 expand + act, depthwise 3x3 (stride) + act, 1x1 project + BN.

    ``light=True`` is the variant used in the attention stages: expand and depthwise
    convs have a bias and no BatchNorm; only the projection is normalised.
    """

    def __init__(self, cin: int, cout: int, stride: int = 1, expand: int = 4, light: bool = False):
        super().__init__()
        mid = cin * expand
        self.inverted_conv = ConvBNAct(cin, mid, 1, bias=light, norm=not light)
        self.depth_conv = ConvBNAct(mid, mid, 3, stride=stride, groups=mid, bias=light, norm=not light)
        self.point_conv = ConvBNAct(mid, cout, 1, act=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.point_conv(self.depth_conv(self.inverted_conv(x)))


class MultiScaleLinearAttention(nn.Module):
    """ReLU linear attention over ``qkv`` and a 5x5-aggregated copy of it (two "scales").

    For ``C`` channels there are ``C / head_dim`` heads per scale; the result
    (``2C`` channels) is projected back to ``C`` by a 1x1 conv + BN.
    """

    def __init__(self, channels: int, head_dim: int = 16, kernel: int = 5, eps: float = 1e-15):
        super().__init__()
        heads = channels // head_dim
        self.head_dim = head_dim
        self.eps = eps
        c3 = 3 * channels
        self.qkv = ConvBNAct(channels, c3, 1, norm=False, act=False)
        self.aggreg = nn.ModuleList([
            nn.Sequential(
                nn.Conv2d(c3, c3, kernel, padding=kernel // 2, groups=c3, bias=False),
                nn.Conv2d(c3, c3, 1, groups=3 * heads, bias=False),
            )
        ])
        self.proj = ConvBNAct(2 * channels, channels, 1, act=False)

    def _attend(self, tokens: torch.Tensor) -> torch.Tensor:
        b, _, h, w = tokens.shape
        d = self.head_dim
        t = tokens.float().reshape(b, -1, 3 * d, h * w)  # (b, groups, 3d, n)
        q = F.relu(t[:, :, :d])
        k = F.relu(t[:, :, d:2 * d])
        v = F.pad(t[:, :, 2 * d:], (0, 0, 0, 1), value=1.0)  # (b, g, d+1, n): v with a row of ones
        kv = torch.matmul(v, k.transpose(-1, -2))  # (b, g, d+1, d)
        out = torch.matmul(kv, q)  # (b, g, d+1, n)
        out = out[:, :, :d] / (out[:, :, d:] + self.eps)
        return out.reshape(b, -1, h, w)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        qkv = self.qkv(x)
        tokens = torch.cat([qkv] + [agg(qkv) for agg in self.aggreg], dim=1)
        out = self._attend(tokens).to(x.dtype)
        return self.proj(out)


class AttentionBlock(nn.Module):
    """Context module (attention, residual) then local module (light MBConv, residual)."""

    def __init__(self, channels: int, head_dim: int, expand: int):
        super().__init__()
        self.context_module = Residual(MultiScaleLinearAttention(channels, head_dim), shortcut=True)
        self.local_module = Residual(MBConv(channels, channels, 1, expand, light=True), shortcut=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.local_module(self.context_module(x))


class Upsample(nn.Module):
    """Parameter-free upsampling by an integer factor (bicubic, align_corners False)."""

    def __init__(self, factor: int, mode: str = "bicubic"):
        super().__init__()
        self.factor = factor
        self.mode = mode

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.factor == 1:
            return x
        return F.interpolate(x, scale_factor=self.factor, mode=self.mode, align_corners=False)


class Backbone(nn.Module):
    """EfficientViT-B0 backbone; :meth:`forward` returns features at strides 8, 16, 32."""

    def __init__(self, widths=(8, 16, 32, 64, 128), depths=(1, 2, 2, 2, 2), head_dim: int = 16, expand: int = 4):
        super().__init__()
        stem = [ConvBNAct(3, widths[0], 3, stride=2)]
        for _ in range(depths[0]):
            stem.append(Residual(DepthwiseSeparable(widths[0], widths[0]), shortcut=True))
        self.input_stem = Sequence(stem)
        stages = []
        cin = widths[0]
        for w, d in zip(widths[1:3], depths[1:3]):  # convolutional stages
            blocks = [Residual(MBConv(cin, w, 2, expand), shortcut=False)]
            blocks += [Residual(MBConv(w, w, 1, expand), shortcut=True) for _ in range(d - 1)]
            stages.append(Sequence(blocks))
            cin = w
        for w, d in zip(widths[3:], depths[3:]):  # attention stages
            blocks = [Residual(MBConv(cin, w, 2, expand, light=True), shortcut=False)]
            blocks += [AttentionBlock(w, head_dim, expand) for _ in range(d)]
            stages.append(Sequence(blocks))
            cin = w
        self.stages = nn.ModuleList(stages)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = self.input_stem(x)
        feats = []
        for stage in self.stages:
            x = stage(x)
            feats.append(x)
        return feats[1:]  # strides 8, 16, 32


class SegHead(nn.Module):
    """Fuse strides 32/16/8 at stride 8, one MBConv, then classify (19 logits)."""

    def __init__(self, in_channels=(128, 64, 32), strides=(32, 16, 8), width: int = 32, expand: int = 4,
                 final_expand: int = 4, n_classes: int = 19):
        super().__init__()
        ops: list[nn.Module] = []
        for c, s in zip(in_channels, strides):
            conv = ConvBNAct(c, width, 1, act=False)
            ops.append(Sequence([conv, Upsample(s // 8)]) if s != 8 else conv)
        self.input_ops = nn.ModuleList(ops)
        self.middle = Sequence([Residual(MBConv(width, width, 1, expand), shortcut=True)])
        self.output_ops = nn.ModuleList([
            Sequence([
                ConvBNAct(width, width * final_expand, 1),
                ConvBNAct(width * final_expand, n_classes, 1, bias=True, norm=False, act=False),
            ])
        ])

    def forward(self, feats: list[torch.Tensor]) -> torch.Tensor:
        s8, s16, s32 = feats
        x = self.input_ops[0](s32) + self.input_ops[1](s16) + self.input_ops[2](s8)
        x = self.middle(x)
        return self.output_ops[0](x)


class EfficientViTSeg(nn.Module):
    """EfficientViT-Seg-B0: ``forward(x (b,3,h,w) normalised) -> logits (b,19,h/8,w/8)``."""

    def __init__(self, n_classes: int = 19):
        super().__init__()
        self.backbone = Backbone()
        self.head = SegHead(n_classes=n_classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.shape[-1] % 32 or x.shape[-2] % 32:
            raise ValueError(f"EfficientViT-Seg needs height and width divisible by 32, got {tuple(x.shape[-2:])}")
        return self.head(self.backbone(x))


def fuse_for_inference(net: nn.Module) -> nn.Module:
    """Fold every BatchNorm into its conv (in place; call after loading weights, in eval mode).

    Same outputs up to float rounding, about 15 % faster on CPU; the state dict then no
    longer has the checkpoint's ``norm`` keys.
    """
    net.eval()
    for module in net.modules():
        if isinstance(module, ConvBNAct):
            module.fuse_norm()
    return net


def efficientvit_seg_b0_cityscapes() -> EfficientViTSeg:
    """An untrained EfficientViT-Seg-B0 with 19 CityScapes classes (load weights with strict=True)."""
    return EfficientViTSeg(n_classes=19)
