"""syrenets-bench: learning the dynamics of physical systems, symbolically and neurally."""

__version__ = "0.1.0"
