"""The application layer: one function per use case, under every face (issue 24).

The faces (the CLI in :mod:`goniolab.commands`, the notebook API in :mod:`goniolab.api`,
the TUI's :mod:`goniolab.tui.session_backend` and the bluesky face) only parse, call a use
case here and present its typed result. Loading a lab config, building a plan, opening a
run store and turning a library error into a :class:`goniolab.errors.UserError` happen
here, once.

Modules (each imported on its own, so ``goniolab --help`` stays light):

- :mod:`goniolab.app.predict`: predict brdf / gloss / albedo from a sample or a map;
- :mod:`goniolab.app.colour`: predict colour, runs colour, fit colour;
- :mod:`goniolab.app.runs`: runs list / show / export / import / annotate / spectra /
  migrate, plot and render of a run;
- :mod:`goniolab.app.lab_scan` (with :mod:`goniolab.app.lab_setup`, :mod:`goniolab.app.lab_gloss`):
  scan, align and resume on a lab, the gloss log, calibrate (``lab_``: a module name is used
  once in the tree, and ``commands/scan.py`` is taken).
"""
