"""Estimators: one module per method behind one streaming interface (base.Estimator)."""

from .base import Estimator, create_estimator, estimator_names

__all__ = ["Estimator", "create_estimator", "estimator_names"]
