"""Training code: everything here may import torch; nothing at runtime imports this package."""
