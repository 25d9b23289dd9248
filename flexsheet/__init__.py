"""flexsheet runtime: node base, codec, transports, launch, bags, CLI (see docs/architecture.md)."""

__version__ = "0.1.0"
