"""The two networks of the USB-C perception pipeline (see training/README.md).

Both take float32 RGB in [0, 1] (8-bit sRGB / 255) and normalise inside the graph, so the Rust
caller feeds raw pixels. Both are small fully convolutional encoder-decoders built from
conv-BN-ReLU blocks: the speed goal is ~100 MFLOP per crop and ~1 GFLOP per feeder window.
"""

import torch
from torch import nn
import torch.nn.functional as F

N_KEYPOINTS = 9
"""8 farthest-point surface keypoints + the box centre (index 8), as the crop labels list them."""

RGB_MEAN = (0.45, 0.45, 0.45)
RGB_STD = (0.25, 0.25, 0.25)


def block(cin, cout, stride=1, dilation=1):
    """3x3 conv + BN + ReLU."""
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride, padding=dilation, dilation=dilation, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class Normalise(nn.Module):
    """(x - mean) / std on the first three (RGB) channels; other channels pass through."""

    def __init__(self, extra_channels=0):
        super().__init__()
        self.extra = extra_channels
        self.register_buffer("mean", torch.tensor(RGB_MEAN).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(RGB_STD).view(1, 3, 1, 1))

    def forward(self, x):
        # The extra channels get mean 0 and std 1, which leaves them exactly as they are: one
        # pass over the whole input instead of slicing the RGB channels out and back in.
        mean, std = self.mean, self.std
        if self.extra:
            zeros = mean.new_zeros(1, self.extra, 1, 1)
            mean, std = torch.cat([mean, zeros], dim=1), torch.cat([std, zeros + 1], dim=1)
        return (x - mean) / std


class Up(nn.Module):
    """x2 bilinear upsampling of the coarse map, 1x1 projection, sum with the skip, 3x3 block.

    The factor is a constant 2, not the skip's size: inputs are multiples of the coarsest stride,
    so the two agree, and a constant lets ONNX Runtime keep the upsampling in its blocked (NCHWc)
    layout instead of reordering around a generic Resize (about 2 ms per 12-crop batch)."""

    def __init__(self, c_coarse, c_skip, cout):
        super().__init__()
        self.proj = nn.Conv2d(c_coarse, cout, 1, bias=False)
        self.skip = nn.Conv2d(c_skip, cout, 1, bias=False) if c_skip != cout else nn.Identity()
        self.fuse = block(cout, cout)

    def forward(self, coarse, skip):
        up = F.interpolate(self.proj(coarse), scale_factor=2.0, mode="bilinear", align_corners=False)
        return self.fuse(up + self.skip(skip))


class KeypointNet(nn.Module):
    """PVNet-style net for one 128x128 crop: input [N, 6, 128, 128] (RGB + one-hot part planes),
    outputs at stride 2: `mask` [N, 1, 64, 64] (logit of the target instance) and `vectors`
    [N, 18, 64, 64] (unit vectors to the 9 keypoints, x then y per keypoint).

    With `unit_vectors = False` (how it is exported) `vectors` are the raw directions: voting
    needs only their direction and normalises them itself, so the graph skips a pass over
    the 18 planes (about 0.5–1 ms per frame's 12 crops in ONNX Runtime).

    The decoder runs to stride 4; the last step upsamples it to stride 2 and adds a 1x1
    projection of the stride-2 features (edges), so almost no work is done at 64x64."""

    WIDTHS = (16, 24, 48, 64, 96)
    """Channels at strides 2, 4, 8, 16, 32 of the committed net (the trainer's default)."""

    PART_SLOTS = {"s2.0.weight": (1, 3)}
    """Tensors with one slice per part, as (axis, first slot): the first conv's part planes."""

    def __init__(self, n_parts, w=WIDTHS):
        super().__init__()
        self.n_parts = n_parts
        self.norm = Normalise(n_parts)
        self.s2 = block(3 + n_parts, w[0], 2)  # 64x64
        self.s4 = nn.Sequential(block(w[0], w[1], 2), block(w[1], w[1]))  # 32x32
        self.s8 = nn.Sequential(block(w[1], w[2], 2), block(w[2], w[2]))  # 16x16
        self.s16 = nn.Sequential(block(w[2], w[3], 2), block(w[3], w[3]))  # 8x8
        self.s32 = nn.Sequential(block(w[3], w[4], 2), block(w[4], w[4]))  # 4x4: whole-part context
        self.u16 = Up(w[4], w[3], w[3])
        self.u8 = Up(w[3], w[2], w[2])
        self.u4 = Up(w[2], w[1], w[1])
        self.skip2 = nn.Conv2d(w[0], w[1], 1)
        self.head = nn.Conv2d(w[1], 1 + 2 * N_KEYPOINTS, 1)
        self.unit_vectors = True

    def forward(self, crop):
        x = self.norm(crop)
        f2 = self.s2(x)
        f4 = self.s4(f2)
        f8 = self.s8(f4)
        f16 = self.s16(f8)
        f32 = self.s32(f16)
        y = self.u16(f32, f16)
        y = self.u8(y, f8)
        y = self.u4(y, f4)
        y = F.interpolate(y, scale_factor=2.0, mode="bilinear", align_corners=False)
        out = self.head(F.relu(y + self.skip2(f2)))
        mask = out[:, :1]
        v = out[:, 1:]
        if not self.unit_vectors:
            return mask, v
        n = v.shape[0]
        v = v.reshape(n, N_KEYPOINTS, 2, v.shape[-2], v.shape[-1])
        v = v / torch.sqrt((v * v).sum(dim=2, keepdim=True) + 1e-6)
        vectors = v.reshape(n, 2 * N_KEYPOINTS, out.shape[-2], out.shape[-1])
        return mask, vectors


class Segmenter(nn.Module):
    """Semantic segmentation + centre offsets for a feeder window: input [N, 3, H, W] (H, W
    multiples of 16), outputs at stride 4: `logits` [N, 1 + P, H/4, W/4] (background, then the
    P parts in catalog order)
    and `offsets` [N, 2, H/4, W/4] (dx, dy in input pixels from the cell centre (4j+1.5,
    4i+1.5) to the centre of the instance the cell belongs to)."""

    OFFSET_SCALE = 32.0
    """Offsets are predicted in units of this many pixels (keeps the regression well scaled)."""

    WIDTHS = (12, 16, 48, 96)
    """Channels at strides 2, 4, 8, 16 of the committed net (the trainer's default)."""

    PART_SLOTS = {"head.weight": (0, 1), "head.bias": (0, 1)}
    """Tensors with one slice per part, as (axis, first slot): the head's class rows."""

    def __init__(self, n_parts, w=WIDTHS):
        super().__init__()
        self.n_parts = n_parts
        self.widths = tuple(w)
        self.norm = Normalise()
        self.s2 = block(3, w[0], 2)
        self.s4 = nn.Sequential(block(w[0], w[1], 2), block(w[1], w[1]))
        self.s8 = nn.Sequential(block(w[1], w[2], 2), block(w[2], w[2]))
        self.s16 = nn.Sequential(
            block(w[2], w[3], 2), block(w[3], w[3], dilation=2), block(w[3], w[3], dilation=4)
        )
        self.u8 = Up(w[3], w[2], w[2])
        self.u4 = Up(w[2], w[1], w[1])
        self.head = nn.Conv2d(w[1], 1 + n_parts + 2, 1)

    def forward(self, image):
        x = self.norm(image)
        f4 = self.s4(self.s2(x))
        f8 = self.s8(f4)
        f16 = self.s16(f8)
        y = self.u4(self.u8(f16, f8), f4)
        out = self.head(y)
        classes = 1 + self.n_parts
        return out[:, :classes], out[:, classes:] * self.OFFSET_SCALE


def count_macs(model, *inputs):
    """Multiply-accumulates per sample of one forward pass, over the Conv2d layers (the bulk)."""
    macs = [0]

    def hook(m, _inp, out):
        k = m.kernel_size[0] * m.kernel_size[1] * (m.in_channels // m.groups)
        macs[0] += out[0].numel() * k

    hooks = [m.register_forward_hook(hook) for m in model.modules() if isinstance(m, nn.Conv2d)]
    with torch.no_grad():
        model.eval()
        model(*inputs)
    for h in hooks:
        h.remove()
    return macs[0]
