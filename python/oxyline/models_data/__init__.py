"""Data files of the built-in models (see oxyline.models and NOTICE)."""
