"""Any estimator's output refined in DragPoser's latent space (refined:base=NAME)."""

from ..record import Method

METHOD = Method(
    "refined",
    "sparse_body.methods.refined.estimator:RefinedEstimator",
    "sparse_body.methods.refined.options:RefinedOptions",
)
