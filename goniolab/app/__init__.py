"""The application layer: one function per use case, under every face (issue 24).

The faces (the CLI in :mod:`goniolab.commands`, the notebook API in :mod:`goniolab.api`,
the TUI's :mod:`goniolab.tui.session_backend` and the bluesky face) only parse, call a use
case here and present its typed result. Loading a lab config, building a plan, opening a
run store and turning a library error into a :class:`goniolab.errors.UserError` happen
here, once.

Modules (each imported on its own, so ``goniolab --help`` stays light):

- :mod:`goniolab.app.predictions`: predict stats / brdf / gloss / albedo from a sample or
  a map;
- :mod:`goniolab.app.colours`: predict colour, runs colour, render of the predicted paint;
  :mod:`goniolab.app.colour_fit`: fit colour;
- :mod:`goniolab.app.stored_runs`: runs list / show / export / import / annotate / spectra
  / migrate, plot of a run;
  :mod:`goniolab.app.sample_maps`: the built-in samples;
- :mod:`goniolab.app.lab_scan` (with :mod:`goniolab.app.lab_setup`, :mod:`goniolab.app.lab_gloss`):
  scan, align and resume on a lab, the gloss log, calibrate (``lab_``: a module name is used
  once in the tree, and ``commands/scan.py`` is taken).
"""
