"""STUB (helper B's placeholder for helper A's reference_impl/materials.py; replaced on merge): the material table."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DIFFUSE, CONDUCTOR, ROUGHCONDUCTOR, DIELECTRIC, ROUGHDIELECTRIC = range(5)
P_REFLECTANCE, P_ETA, P_K, P_TRANSMITTANCE = 0, 3, 6, 9
P_ALPHA, P_DISTRIBUTION, P_SAMPLE_VISIBLE, P_IOR, P_TWO_SIDED, P_MIRROR = 12, 13, 14, 15, 16, 17
NUM_PARAMS = 20


@dataclass(frozen=True)
class Materials:
    kind: np.ndarray
    params: np.ndarray

    @classmethod
    def diffuse(cls, reflectance, two_sided) -> "Materials":
        reflectance = np.asarray(reflectance, np.float64).reshape(-1, 3)
        params = np.zeros((len(reflectance), NUM_PARAMS))
        params[:, 0:3] = reflectance
        params[:, P_TWO_SIDED] = np.asarray(two_sided, np.float64)
        return cls(np.zeros(len(reflectance), np.int64), params)

    @property
    def all_diffuse(self) -> bool:
        return bool(np.all(self.kind == DIFFUSE))

    def __len__(self) -> int:
        return len(self.kind)
