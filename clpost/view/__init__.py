"""``clpost view``: the camera live in a browser (docs/view.md).

:mod:`.session` is the model (frames, the camera, plans per quality, exposure tools, command line
and camera track) and needs no web framework; :mod:`.controls` generates the controls from the
parameter declarations; :mod:`.app` is the trame page; :mod:`.command` the CLI subcommand.
"""
