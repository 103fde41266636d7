"""Smoothers over stored filter results."""

from .imm_smoother import IMMSmoothed, imm_smooth
from .rts import rts_smooth

__all__ = ["IMMSmoothed", "imm_smooth", "rts_smooth"]
