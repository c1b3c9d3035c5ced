"""Differentiable kinematics and the reconstruction losses the stylizer trainers share: generated
``[root | rot6d]`` frames are turned into joint rotations, positions and velocities (the maths of
``core.features.encode``), and compared with real ones in comparable units."""

from __future__ import annotations

from typing import Protocol

import numpy as np
import torch
from torch import nn

from motion_style_ros.core.features import feature_layout
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.models.style_erd import OUT_ROOT
from motion_style_ros.training.data import FPS


class Weights(Protocol):
    """The loss weights a trainer's config gives the reconstruction terms."""

    w_pos: float
    w_vel: float
    w_root: float


class Kinematics(nn.Module):
    """The ``pos`` and ``vel`` feature blocks from ``[root | rot6d]`` frames, differentiably: forward
    kinematics of the canonical skeleton in the facing frame, and velocities as the root velocity
    plus the change of facing-relative positions (the maths of ``core.features.encode``)."""

    def __init__(self) -> None:
        super().__init__()
        sk = canonical()
        joints = list(feature_layout(sk).joints)
        self.parents = [joints.index(sk.parents[j]) if k else -1 for k, j in enumerate(joints)]
        self.register_buffer("offsets", torch.tensor(sk.offsets[joints], dtype=torch.float32))

    def forward(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(B, T, 130)`` -> local rotation matrices ``(B, T, J, 3, 3)``, positions ``(B, T, J, 3)``,
        velocities of frames 1.. ``(B, T-1, J, 3)``."""
        root = frames[..., :OUT_ROOT]
        d6 = frames[..., OUT_ROOT:].unflatten(-1, (-1, 6))
        x, y = d6[..., :3], d6[..., 3:]
        local = torch.stack([x, y, torch.linalg.cross(x, y)], dim=-1)
        zero = torch.zeros_like(root[..., :1])
        g_rot = [local[..., 0, :, :]]
        g_pos = [torch.cat([zero, root[..., 2:3], zero], dim=-1)]
        for k, p in enumerate(self.parents[1:], start=1):
            g_pos.append(g_pos[p] + g_rot[p] @ self.offsets[k])
            g_rot.append(g_rot[p] @ local[..., k, :, :])
        pos = torch.stack(g_pos, dim=-2)
        # Previous positions turned into the current facing frame (a turn by -yaw rate / fps).
        turn = -root[..., 1:, 3:4] / FPS
        cos, sin = torch.cos(turn), torch.sin(turn)
        prev = pos[..., :-1, :, :]
        prev = torch.stack([cos * prev[..., 0] + sin * prev[..., 2], prev[..., 1],
                            cos * prev[..., 2] - sin * prev[..., 0]], dim=-1)
        ground = torch.stack([root[..., 1:, 0], torch.zeros_like(root[..., 1:, 0]), root[..., 1:, 1]], -1)
        vel = ground[..., None, :] + (pos[..., 1:, :, :] - prev) * FPS
        return local, pos, vel


def rotation_angle(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Angle (rad) between rotation matrices ``(..., 3, 3)``; the clamp keeps acos' gradient finite."""
    cos = ((a * b).sum(dim=(-2, -1)) - 1) / 2
    return torch.acos(cos.clamp(-1 + 1e-6, 1 - 1e-6))


def pose(pos: torch.Tensor) -> torch.Tensor:
    """Joint positions ``(..., J, 3)`` relative to the pelvis: the body's pose without its path."""
    return pos - pos[..., :1, :]


class Losses(nn.Module):
    """Per-term losses in comparable units, from the train-set statistics of the feature blocks."""

    def __init__(self, weights: Weights, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.weights = weights
        self.kinematics = Kinematics()
        s = feature_layout().slices
        self.pos_scale, self.vel_scale = (float(np.sqrt(np.mean(std[s[b]] ** 2))) for b in ("pos", "vel"))
        self.register_buffer("root_std", torch.as_tensor(std[s["root"]], dtype=torch.float32))
        # critic inputs: normalised rot6d, pos and vel blocks (content) or pos and vel (discriminator)
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
        self.rot_cols = slice(s["rot6d"].start, s["rot6d"].stop)
        self.pv_cols = slice(s["pos"].start, s["vel"].stop)
        self.contact_cols = s["contact"]
        sk = canonical()
        joints = list(feature_layout(sk).joints)
        self.feet = [joints.index(f) for f in sk.feet]  # the contact block's order

    def views(self, frames: torch.Tensor) -> dict[str, torch.Tensor]:
        """Rotations, positions, velocities of ``[root | rot6d]`` frames, and the critics' inputs
        (frames 1..: the first has no velocity)."""
        local, pos, vel = self.kinematics(frames)
        pv = torch.cat([pos[:, 1:].flatten(-2), vel.flatten(-2)], dim=-1)
        pv = (pv - self.mean[self.pv_cols]) / self.std[self.pv_cols]
        rot6d = (frames[:, 1:, OUT_ROOT:] - self.mean[self.rot_cols]) / self.std[self.rot_cols]
        return {"root": frames[..., :OUT_ROOT], "local": local, "pos": pos, "vel": vel,
                "pv": pv, "content": torch.cat([rot6d, pv], dim=-1)}

    def reconstruction(self, out: dict[str, torch.Tensor], real: dict[str, torch.Tensor]
                       ) -> dict[str, torch.Tensor]:
        """The weighted rotation, position, velocity and root terms between two :meth:`views`."""
        w = self.weights
        return {
            "rot": rotation_angle(out["local"], real["local"]).pow(2).mean(),
            "pos": w.w_pos * ((out["pos"] - real["pos"]) / self.pos_scale).pow(2).sum(-1).mean(),
            "vel": w.w_vel * ((out["vel"] - real["vel"]) / self.vel_scale).pow(2).sum(-1).mean(),
            "root": w.w_root * ((out["root"] - real["root"]) / self.root_std).pow(2).mean(),
        }

    def distance(self, out: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """The :meth:`reconstruction` terms between two ``[root | rot6d]`` windows, summed."""
        return sum(self.reconstruction(self.views(out), self.views(target)).values())

    def foot(self, out: dict[str, torch.Tensor], x: torch.Tensor) -> torch.Tensor:
        """Squared velocity (train-std units) of the foot joints the input ``x`` (features) holds
        in contact, per frame 1.. (the first has no velocity)."""
        contact = x[:, 1:, self.contact_cols]
        speed = (out["vel"][:, :, self.feet] / self.vel_scale).pow(2).sum(-1)
        return (contact * speed).mean()


def val_scores(rec: dict[str, torch.Tensor]) -> dict[str, float]:
    """A validation's reconstruction terms (:meth:`Losses.reconstruction`) as the log reports them:
    their sum and the rotation error in degrees RMS."""
    return {"val_rec": round(sum(rec.values()).item(), 5),
            "val_rot_deg": round(float(np.degrees(np.sqrt(rec["rot"].item()))), 3)}
