"""Estimators: one module per method behind one streaming interface (base.Estimator)."""
from .base import ESTIMATORS, Estimator, create_estimator

__all__ = ["ESTIMATORS", "Estimator", "create_estimator"]
