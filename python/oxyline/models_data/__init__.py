"""Data files of the built-in models (see oxyline.catalogue and NOTICE)."""
