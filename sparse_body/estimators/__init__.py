"""Estimators: one module per method behind one streaming interface (base.Estimator); they
are made by name with methods.factory.create_estimator."""

from .base import Estimator

__all__ = ["Estimator"]
