"""gpis-harness: grasp planning under shape uncertainty with Gaussian process implicit
surfaces, validated by physics."""

__version__ = "0.1.0"
