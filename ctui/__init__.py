"""ctui: terminal-first CT/MRI slice series to measured 3D models."""

__version__ = "0.1.0"
