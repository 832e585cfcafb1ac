"""The package's version (``servo.__version__``), in a module of its own at the bottom of
the import graph, so that any module may read it without importing the ``servo`` facade."""
__version__ = "0.1.0"
