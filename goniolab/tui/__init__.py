"""The goniolab Textual UI (the only package that imports textual).

:class:`~goniolab.tui.app.GonioApp` shows measured points beside the model's prediction,
live, with instrument status, scan controls, a glossmeter log and a runs browser.
"""
