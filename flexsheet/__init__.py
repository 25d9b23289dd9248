"""flexsheet: the encountered-type visual haptic display using a flexible sheet — the library (runtime, model,
the algorithm packages, the twin, experiments); the nodes in ``nodes/`` are its adapters
(docs/architecture.md)."""

__version__ = "0.10.0"
