"""Smoothers over stored filter results."""

from .rts import rts_smooth

__all__ = ["rts_smooth"]
