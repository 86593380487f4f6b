"""Sub-commands of the ``goniolab`` CLI: one module each, each exposing ``register(sub)``."""
