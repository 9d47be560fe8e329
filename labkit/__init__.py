"""labkit: the vibration lab's toolkit for thin-film PZT microrobots."""

__version__ = "0.1.0"
