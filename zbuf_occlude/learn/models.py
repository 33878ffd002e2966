"""The three classifiers of Sryamkin et al. 2023, Table 3: PointNet, VoxNet and 3DmFV-Net.

Every model takes a batch of point clouds ``(B, N, 3) float32`` in object units (each
cloud centred on its bounding box with maximum extent 1, z up; :func:`normalize_clouds`)
and returns class logits ``(B, K)``; VoxNet and 3DmFV-Net turn the points into their own
input (an occupancy grid, a grid of Fisher vectors) inside ``forward``, so one training
loop serves all three.  ``width`` scales every channel count (1.0 = the papers' sizes;
the ``quick`` scale of the experiments uses less to fit a 2-core CPU).

References
----------
* C. R. Qi, H. Su, K. Mo, L. J. Guibas, "PointNet: Deep Learning on Point Sets for 3D
  Classification and Segmentation", CVPR 2017.
* D. Maturana, S. Scherer, "VoxNet: A 3D Convolutional Neural Network for Real-Time
  Object Recognition", IROS 2015.
* Y. Ben-Shabat, M. Lindenbaum, A. Fischer, "3DmFV: Three-Dimensional Point Cloud
  Classification in Real-Time Using Convolutional Neural Networks", IEEE RA-L 3(4), 2018.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from zbuf_occlude.errors import InvalidInputError

__all__ = [
    "MODELS",
    "PointNet",
    "TNet",
    "VoxNet",
    "FisherVectorLayer",
    "ThreeDmFVNet",
    "build_model",
    "check_model_config",
    "MAX_WIDTH",
    "MAX_CLASSES",
    "MAX_FV_GRID",
    "orthogonality_loss",
    "voxelize",
    "normalize_clouds",
]

MODELS = ("pointnet", "voxnet", "3dmfv")
#: Largest channel multiplier: 8.  The paper's models are width 1.0; parameters grow with its
#: square, so 8 is 64x (~220M for PointNet, ~0.9 GB); a checkpoint saying 1e9 would ask 768 GB.
MAX_WIDTH = 8.0
#: Most classes a model may have: 1,000 (ModelNet40 has 40, ShapeNet 55, ImageNet 1,000).
MAX_CLASSES = 1000
#: Most 3DmFV Gaussians per side: 16 (the 3DmFV paper uses 3 to 8; memory grows with its cube).
MAX_FV_GRID = 16


def _c(n: int, width: float) -> int:
    return max(4, int(round(n * width)))


def normalize_clouds(points: torch.Tensor) -> torch.Tensor:
    """Centre each cloud's bounding box on 0 and scale its maximum extent to 1 (paper §4.1).

    Parameters
    ----------
    points : (B, N, 3) float tensor

    Returns
    -------
    (B, N, 3) tensor, same dtype
    """
    lo, hi = points.min(dim=1, keepdim=True).values, points.max(dim=1, keepdim=True).values
    extent = (hi - lo).amax(dim=2, keepdim=True).clamp_min(1e-9)
    return (points - (lo + hi) / 2) / extent


# -- PointNet ------------------------------------------------------------------------------
class SharedMLP(nn.Module):
    """PointNet's shared MLP ("1×1 convolutions"): per-point Linear → BatchNorm → ReLU, channels last.

    ``(B, N, C_in)`` → ``(B, N, C_out)``.  Equivalent to ``Conv1d(kernel_size=1)`` on
    ``(B, C, N)`` and several times faster on CPU.
    """

    def __init__(self, channels: list[int]):
        super().__init__()
        self.linears = nn.ModuleList(nn.Linear(a, b) for a, b in zip(channels[:-1], channels[1:]))
        self.norms = nn.ModuleList(nn.BatchNorm1d(b) for b in channels[1:])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, n, _ = x.shape
        for lin, bn in zip(self.linears, self.norms):
            x = F.relu(bn(lin(x).reshape(b * n, -1))).reshape(b, n, -1)
        return x


class TNet(nn.Module):
    """PointNet's transform net: predicts a ``k × k`` matrix from ``(B, N, k)`` per-point
    features, initialised to the identity (Qi et al. 2017, §4.2, Appendix C)."""

    def __init__(self, k: int, width: float = 1.0):
        super().__init__()
        self.k = k
        c1, c2, c3, f1, f2 = (_c(n, width) for n in (64, 128, 1024, 512, 256))
        self.mlp = SharedMLP([k, c1, c2, c3])
        self.fc = nn.Sequential(
            nn.Linear(c3, f1), nn.BatchNorm1d(f1), nn.ReLU(),
            nn.Linear(f1, f2), nn.BatchNorm1d(f2), nn.ReLU(),
        )  # fmt: skip
        self.out = nn.Linear(f2, k * k)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` (B, N, k) → (B, k, k)."""
        h = self.mlp(x).amax(dim=1)
        eye = torch.eye(self.k, device=x.device, dtype=x.dtype)
        return self.out(self.fc(h)).view(-1, self.k, self.k) + eye


def orthogonality_loss(transform: torch.Tensor) -> torch.Tensor:
    """PointNet's regulariser ``mean_b ||I − A_b A_bᵀ||_F²`` (Qi et al. 2017, Eq. 2).

    Parameters
    ----------
    transform : (B, k, k) tensor

    Returns
    -------
    scalar tensor, 0 exactly for orthogonal matrices
    """
    k = transform.shape[-1]
    eye = torch.eye(k, device=transform.device, dtype=transform.dtype)
    diff = eye - transform @ transform.transpose(1, 2)
    return (diff**2).sum(dim=(1, 2)).mean()


class PointNet(nn.Module):
    """PointNet classification network (Qi et al., CVPR 2017, Fig. 2), vanilla layout.

    Input transform (T-net 3×3) → shared MLP(64, 64) → feature transform (T-net 64×64) →
    shared MLP(64, 128, 1024) → max pool → FC 512, 256 (dropout keep 0.7) → K.

    Parameters
    ----------
    n_classes : int
    width : float
        Channel multiplier (1.0 = the paper).
    reg_weight : float
        Weight of :func:`orthogonality_loss` on the feature transform (paper: 0.001).

    Notes
    -----
    ``forward(points)`` takes ``(B, N, 3)`` float32 object-unit clouds and returns logits
    ``(B, K)``; after each call ``self.regularizer`` holds the weighted orthogonality loss
    of that batch's feature transform, which the training loop adds to the loss.
    """

    def __init__(self, n_classes: int, width: float = 1.0, reg_weight: float = 1e-3):
        super().__init__()
        c64, c128, c1024, f512, f256 = (_c(n, width) for n in (64, 128, 1024, 512, 256))
        self.reg_weight = reg_weight
        self.input_transform = TNet(3, width)
        self.mlp1 = SharedMLP([3, c64, c64])
        self.feature_transform = TNet(c64, width)
        self.mlp2 = SharedMLP([c64, c128, c1024])
        self.head = nn.Sequential(
            nn.Linear(c1024, f512), nn.BatchNorm1d(f512), nn.ReLU(),
            nn.Linear(f512, f256), nn.BatchNorm1d(f256), nn.ReLU(), nn.Dropout(0.3),
            nn.Linear(f256, n_classes),
        )  # fmt: skip
        self.regularizer = torch.zeros(())
        self.last_transforms: tuple[torch.Tensor, torch.Tensor] | None = None

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        # row-vector convention of the paper's code: x (B, N, k) @ T (B, k, k)
        t_in = self.input_transform(points)
        x = self.mlp1(torch.bmm(points, t_in))
        t_feat = self.feature_transform(x)
        x = self.mlp2(torch.bmm(x, t_feat)).amax(dim=1)
        self.last_transforms = (t_in, t_feat)
        self.regularizer = self.reg_weight * orthogonality_loss(t_feat)
        return self.head(x)


# -- VoxNet --------------------------------------------------------------------------------
def voxelize(points: torch.Tensor, grid: int = 32) -> torch.Tensor:
    """Binary occupancy grid of normalised clouds (VoxNet's "binary" occupancy model).

    Parameters
    ----------
    points : (B, N, 3) tensor
        Object units in [-0.5, 0.5]³ (max extent 1, centred); points outside are clamped.
    grid : int
        Cells per side (VoxNet: 32, with the object inside the central 24³, §3.2).

    Returns
    -------
    (B, 1, grid, grid, grid) float tensor of 0/1, indexed [b, 0, x, y, z]
    """
    b, n, _ = points.shape
    margin = 4.0 / 32.0  # the 24³ object region inside 32³ (VoxNet's padding), as a fraction
    inner = grid * (1.0 - 2 * margin)
    idx = ((points + 0.5) * inner + grid * margin).floor().long().clamp_(0, grid - 1)
    flat = (idx[..., 0] * grid + idx[..., 1]) * grid + idx[..., 2]  # (B, N)
    occ = torch.zeros(b, grid**3, device=points.device, dtype=points.dtype)
    occ.scatter_(1, flat, 1.0)
    return occ.view(b, 1, grid, grid, grid)


class VoxNet(nn.Module):
    """VoxNet (Maturana & Scherer, IROS 2015, §3.3) on a 32³ binary occupancy grid.

    Conv(32, 5³, stride 2) → Conv(32, 3³) → MaxPool(2³) → FC 128 → K, leaky ReLU
    (slope 0.1), dropout 0.2 / 0.3 / 0.4 after the two convolutions and the FC layer.

    Parameters
    ----------
    n_classes : int
    width : float
        Channel multiplier (1.0 = the paper).
    grid : int
        Occupancy grid side (32 in the paper).

    Notes
    -----
    ``forward(points)``: ``(B, N, 3)`` float32 normalised clouds → :func:`voxelize` →
    ``(B, 1, 32, 32, 32)`` → logits ``(B, K)``.
    """

    def __init__(self, n_classes: int, width: float = 1.0, grid: int = 32):
        super().__init__()
        c = _c(32, width)
        self.grid = grid
        self.features = nn.Sequential(
            nn.Conv3d(1, c, 5, stride=2), nn.LeakyReLU(0.1), nn.Dropout(0.2),
            nn.Conv3d(c, c, 3), nn.LeakyReLU(0.1), nn.MaxPool3d(2), nn.Dropout(0.3),
        )  # fmt: skip
        side = ((grid - 5) // 2 + 1 - 2) // 2
        self.head = nn.Sequential(
            nn.Flatten(), nn.Linear(c * side**3, _c(128, width)), nn.LeakyReLU(0.1), nn.Dropout(0.4),
            nn.Linear(_c(128, width), n_classes),
        )  # fmt: skip

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(voxelize(points, self.grid)))


# -- 3DmFV ---------------------------------------------------------------------------------
class FisherVectorLayer(nn.Module):
    """3D modified Fisher vectors on a uniform ``m × m × m`` grid of Gaussians (Ben-Shabat et al. 2018, §III).

    Gaussians: centres on the grid ``μ_k ∈ [-1, 1]³`` (cell centres), equal weights
    ``w_k = 1/m³``, isotropic ``σ = 1/m``.  Points are first scaled into the unit sphere
    (``2·p`` for clouds of max extent 1 centred at 0, then divided by their largest norm if
    above 1).  With soft assignments ``γ_k(p) = w_k N(p; μ_k, σ²I) / Σ_j w_j N(p; μ_j, σ²I)``
    and per-point Fisher components (T points)

        G_α = (γ_k − w_k) / (T √w_k),
        G_μ = γ_k (p − μ_k) / (T σ √w_k)              (3 values),
        G_σ = γ_k ((p − μ_k)² / σ² − 1) / (T √(2 w_k))  (3 values),

    the 3DmFV of a cloud is, per Gaussian, ``[max, sum] of G_α`` and ``[max, min, sum]``
    of each of the 6 other components: 20 values, laid out as ``(B, 20, m, m, m)``.
    With ``normalize`` (the paper's default) each of the three groups is power-normalised
    (``sign(x)·|x|^0.5``) and L2-normalised over the Gaussians.

    Parameters
    ----------
    m : int
        Gaussians per side (paper: 8 for ModelNet40; K = m³).
    normalize : bool
    """

    def __init__(self, m: int = 8, normalize: bool = True):
        super().__init__()
        self.m = m
        self.normalize = normalize
        c = (torch.arange(m, dtype=torch.float32) + 0.5) / m * 2 - 1
        mu = torch.stack(torch.meshgrid(c, c, c, indexing="ij"), dim=-1).reshape(-1, 3)
        self.register_buffer("mu", mu)  # (K, 3), K = m³, index (i*m + j)*m + k
        self.sigma = 1.0 / m
        self.weight = 1.0 / m**3

    @staticmethod
    def to_unit_sphere(points: torch.Tensor) -> torch.Tensor:
        """``(B, N, 3)`` normalised clouds (extent 1) → inside the unit sphere."""
        p = points * 2.0
        r = p.norm(dim=2).amax(dim=1, keepdim=True).clamp_min(1.0)
        return p / r.unsqueeze(-1)

    def per_point(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Soft assignments and Fisher components of points already in the unit sphere.

        Returns
        -------
        gamma : (B, N, K)
        d_mu, d_sig : (B, N, K, 3)  (without the 1/T factor)
        """
        diff = (points.unsqueeze(2) - self.mu) / self.sigma  # (B, N, K, 3)
        log_p = -0.5 * (diff**2).sum(-1)  # equal weights and σ: the constants cancel
        gamma = torch.softmax(log_p, dim=2)
        w = self.weight
        d_mu = gamma.unsqueeze(-1) * diff / math.sqrt(w)
        d_sig = gamma.unsqueeze(-1) * (diff**2 - 1) / math.sqrt(2 * w)
        return gamma, d_mu, d_sig

    def forward(self, points: torch.Tensor, *, unit_sphere: bool = False) -> torch.Tensor:
        """``(B, N, 3)`` clouds (max extent 1, or already in the unit sphere with ``unit_sphere``) → ``(B, 20, m, m, m)``."""
        p = points if unit_sphere else self.to_unit_sphere(points)
        b, n, _ = p.shape
        gamma, d_mu, d_sig = self.per_point(p)
        w = self.weight
        d_pi = (gamma - w) / (math.sqrt(w) * n)  # (B, N, K)
        d_mu, d_sig = d_mu / n, d_sig / n
        g_pi = torch.stack([d_pi.amax(1), d_pi.sum(1)], dim=-1)  # (B, K, 2)
        g_mu = torch.cat([d_mu.amax(1), d_mu.amin(1), d_mu.sum(1)], dim=-1)  # (B, K, 9)
        g_sig = torch.cat([d_sig.amax(1), d_sig.amin(1), d_sig.sum(1)], dim=-1)  # (B, K, 9)
        if self.normalize:
            groups = []
            for g in (g_pi, g_mu, g_sig):
                g = torch.sign(g) * g.abs().sqrt()
                groups.append(F.normalize(g, dim=1))
            g_pi, g_mu, g_sig = groups
        fv = torch.cat([g_pi, g_mu, g_sig], dim=-1)  # (B, K, 20)
        m = self.m
        return fv.transpose(1, 2).reshape(b, 20, m, m, m)


class _Inception3d(nn.Module):
    """3DmFV's inception module: a 1³ conv, 1³→3³ and 1³→5³ convs, and a 3³ average pool → 1³
    conv, concatenated (4·c channels); each conv with batch norm and ReLU."""

    def __init__(self, cin: int, c: int):
        super().__init__()

        def conv(ci: int, co: int, k: int) -> nn.Sequential:
            return nn.Sequential(nn.Conv3d(ci, co, k, padding=k // 2), nn.BatchNorm3d(co), nn.ReLU())

        self.b1 = conv(cin, c, 1)
        self.b3 = nn.Sequential(conv(cin, c // 2, 1), conv(c // 2, c, 3))
        self.b5 = nn.Sequential(conv(cin, c // 2, 1), conv(c // 2, c, 5))
        self.bp = conv(cin, c, 1)
        self.out_channels = 4 * c

    @staticmethod
    def _avg_pool_same(x: torch.Tensor) -> torch.Tensor:
        # 3³ average pool, stride 1, TensorFlow's "SAME" padding (padding not counted): works on 2³ grids too
        ones = torch.ones_like(x[:, :1])
        pad = (1, 1, 1, 1, 1, 1)
        total = F.avg_pool3d(F.pad(x, pad), 3, stride=1)
        count = F.avg_pool3d(F.pad(ones, pad), 3, stride=1)
        return total / count

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.b1(x), self.b3(x), self.b5(x), self.bp(self._avg_pool_same(x))], dim=1)


class ThreeDmFVNet(nn.Module):
    """3DmFV-Net (Ben-Shabat et al., RA-L 2018, Fig. 3): 3DmFV grid → 3D inception CNN → FC.

    Inception(64) ×2 → MaxPool(2³) → Inception(128) ×2 → MaxPool(2³) → Inception(256) ×2 →
    MaxPool(2³) → FC 1024, 256, 128 (dropout keep 0.7) → K, for a grid of ``m = 8``.

    Parameters
    ----------
    n_classes : int
    m : int
        Gaussians per side (8 in the paper; ``m`` must be ≥ 8 for three poolings to
        leave a cell, smaller grids skip the last pooling steps).
    width : float
        Channel multiplier (1.0 = the paper).

    Notes
    -----
    ``forward(points)``: ``(B, N, 3)`` float32 clouds (max extent 1, centred) →
    :class:`FisherVectorLayer` ``(B, 20, m, m, m)`` → logits ``(B, K)``.
    """

    def __init__(self, n_classes: int, m: int = 8, width: float = 1.0):
        super().__init__()
        self.fv = FisherVectorLayer(m)
        layers: list[nn.Module] = []
        cin, side = 20, m
        for c in (_c(64, width), _c(128, width), _c(256, width)):
            i1 = _Inception3d(cin, c)
            i2 = _Inception3d(i1.out_channels, c)
            layers += [i1, i2]
            cin = i2.out_channels
            if side >= 2:
                layers.append(nn.MaxPool3d(2))
                side //= 2
        self.cnn = nn.Sequential(*layers)
        f1, f2, f3 = (_c(n, width) for n in (1024, 256, 128))
        self.head = nn.Sequential(
            nn.Flatten(), nn.Linear(cin * side**3, f1), nn.BatchNorm1d(f1), nn.ReLU(), nn.Dropout(0.3),
            nn.Linear(f1, f2), nn.BatchNorm1d(f2), nn.ReLU(), nn.Dropout(0.3),
            nn.Linear(f2, f3), nn.BatchNorm1d(f3), nn.ReLU(), nn.Dropout(0.3),
            nn.Linear(f3, n_classes),
        )  # fmt: skip

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        return self.head(self.cnn(self.fv(points)))


#: Batch-norm momentum of PointNet and 3DmFV-Net: their code starts the moving-average decay at
#: 0.5 (torch momentum = 1 − decay), which lets the running statistics follow a short run.
BN_MOMENTUM = 0.5


def _set_bn_momentum(model: nn.Module, momentum: float) -> nn.Module:
    for mod in model.modules():
        if isinstance(mod, nn.modules.batchnorm._BatchNorm):
            mod.momentum = momentum
    return model


def check_model_config(name: object, n_classes: object, width: object, fv_grid: object) -> tuple[str, int, float, int]:
    """The model settings, checked before anything is built (a checkpoint's config is untrusted).

    Returns
    -------
    (name, n_classes, width, fv_grid) : (str, int, float, int)

    Raises
    ------
    InvalidInputError
        The message starts with the field: ``model`` not one of :data:`MODELS`, ``n_classes``
        not an integer in [2, :data:`MAX_CLASSES`], ``width`` not a number in
        (0, :data:`MAX_WIDTH`], ``fv_grid`` not an integer in [1, :data:`MAX_FV_GRID`].
    """
    if not isinstance(name, str) or name not in MODELS:
        raise InvalidInputError(f"model: unknown model {name!r}; choose from {', '.join(MODELS)}")

    def integer(field: str, value: object, lo: int, hi: int, why: str) -> int:
        if isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise InvalidInputError(f"{field}: must be an integer in [{lo}, {hi:,}], got {value!r}")
        if not lo <= int(value) <= hi:
            raise InvalidInputError(f"{field}: {int(value):,} is outside [{lo}, {hi:,}] ({why})")
        return int(value)

    n_classes = integer("n_classes", n_classes, 2, MAX_CLASSES, "a classifier needs at least 2 classes; see MAX_CLASSES")
    fv_grid = integer("fv_grid", fv_grid, 1, MAX_FV_GRID, "Gaussians per side; see MAX_FV_GRID")
    if isinstance(width, bool) or not isinstance(width, (int, float, np.integer, np.floating)) or not 0 < width <= MAX_WIDTH:
        raise InvalidInputError(f"width: must be a number in (0, {MAX_WIDTH:g}], got {width!r}")
    return name, n_classes, float(width), fv_grid


def build_model(name: str, n_classes: int, *, width: float = 1.0, fv_grid: int = 8) -> nn.Module:
    """A model by name (:data:`MODELS`).

    Raises
    ------
    InvalidInputError
        Unknown name or settings out of bounds (:func:`check_model_config`), checked before
        any layer is allocated.
    """
    name, n_classes, width, fv_grid = check_model_config(name, n_classes, width, fv_grid)
    if name == "pointnet":
        return _set_bn_momentum(PointNet(n_classes, width), BN_MOMENTUM)
    if name == "voxnet":
        return VoxNet(n_classes, width)
    if name == "3dmfv":
        return _set_bn_momentum(ThreeDmFVNet(n_classes, m=fv_grid, width=width), BN_MOMENTUM)
    raise InvalidInputError(f"unknown model {name!r}; choose from {', '.join(MODELS)}")


def count_parameters(model: nn.Module) -> int:
    """Trainable parameters."""
    return int(sum(np.prod(p.shape) for p in model.parameters() if p.requires_grad))
