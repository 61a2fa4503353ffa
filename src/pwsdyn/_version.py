"""The version of pwsdyn, in a module of its own so that any part of the library can record it
(in files, in provenance) without importing the package's top level."""

__version__ = "0.1.0"
