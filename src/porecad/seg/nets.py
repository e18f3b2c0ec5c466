"""Networks of 000 §6.2.3–6.2.4 (PyTorch; MONAI for the localiser's conventional U-Net).

* :class:`SegUNet3D` — the per-disc segmentation network of Table 6.2: per
  level two 3×3×3 convolutions with dropout 0.2 between them, batch
  normalisation and ReLU, 2×2×2 max pooling; the expanding path up-samples
  with 2×2×2 transposed convolutions, concatenates the skip and applies two
  3×3×3 convolutions; a 1×1×1 convolution gives one logit (sigmoid → IVD
  probability). ``features=(32, 64, 128)`` and 3 input channels give the
  ≈1.4 M parameters of §6.2.4.2 (notes §9.6: 1.36 M). 'Same' padding is used
  (000's "unpadded" convolutions do not fit its same-size outputs; notes §6.4).
* :func:`localiser_3d` — the "conventional 3D U-Net" of §6.2.4.1 that finds
  disc centres, run at reduced resolution: MONAI's ``UNet``.
* :func:`unet_2d` — the 2-D slice U-Net of §6.2.3 (MONAI ``UNet`` with
  ``spatial_dims=2``; 000's 64…1024 channels are the default of the paper, the
  CLI defaults are smaller for CPUs).
"""

from __future__ import annotations

import torch
from torch import nn


class _Block(nn.Sequential):
    def __init__(self, cin, cout, dropout):
        super().__init__(
            nn.Conv3d(cin, cout, 3, padding=1), nn.BatchNorm3d(cout), nn.ReLU(inplace=True),
            nn.Dropout3d(dropout) if dropout > 0 else nn.Identity(),
            nn.Conv3d(cout, cout, 3, padding=1), nn.BatchNorm3d(cout), nn.ReLU(inplace=True))


class SegUNet3D(nn.Module):
    """The 3-level per-disc U-Net of 000 Table 6.2 (logits out)."""

    def __init__(self, in_channels: int = 3, features=(32, 64, 128), dropout: float = 0.2):
        super().__init__()
        f = list(features)
        self.down = nn.ModuleList()
        cin = in_channels
        for c in f:
            self.down.append(_Block(cin, c, dropout))
            cin = c
        self.pool = nn.MaxPool3d(2)
        self.up = nn.ModuleList()
        self.dec = nn.ModuleList()
        for c_hi, c_lo in zip(f[::-1][:-1], f[::-1][1:]):
            self.up.append(nn.ConvTranspose3d(c_hi, c_lo, 2, stride=2))
            self.dec.append(_Block(2 * c_lo, c_lo, dropout))
        self.head = nn.Conv3d(f[0], 1, 1)
        for m in self.modules():  # He initialisation (000 §6.2.5)
            if isinstance(m, (nn.Conv3d, nn.ConvTranspose3d)):
                nn.init.kaiming_normal_(m.weight, nonlinearity="relu")
                nn.init.zeros_(m.bias)

    def forward(self, x):
        skips = []
        for i, block in enumerate(self.down):
            x = block(x)
            if i < len(self.down) - 1:
                skips.append(x)
                x = self.pool(x)
        for up, dec in zip(self.up, self.dec):
            x = up(x)
            x = dec(torch.cat([x, skips.pop()], dim=1))
        return self.head(x)


def localiser_3d(in_channels: int, features=(8, 16, 32)):
    """MONAI 3-D U-Net for the coarse disc mask whose components give the disc centres."""
    from monai.networks.nets import UNet
    f = tuple(int(x) for x in features)
    return UNet(spatial_dims=3, in_channels=in_channels, out_channels=1, channels=f,
                strides=tuple([2] * (len(f) - 1)), num_res_units=0, norm="batch")


def unet_2d(in_channels: int, features=(16, 32, 64, 128)):
    """MONAI 2-D U-Net for slices (000 Fig. 6.2: features 64, 128, 256, 512, 1024)."""
    from monai.networks.nets import UNet
    f = tuple(int(x) for x in features)
    return UNet(spatial_dims=2, in_channels=in_channels, out_channels=1, channels=f,
                strides=tuple([2] * (len(f) - 1)), num_res_units=0, norm="batch")


def count_parameters(model) -> int:
    return int(sum(p.numel() for p in model.parameters()))
