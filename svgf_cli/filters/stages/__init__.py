"""The stages of the filter's pipelines, one per module (ordered by ``filters.pipeline``).

Each is thin host code: it turns the settings into kernel arguments and calls the kernels
in ``svgf_cli.filters``; the buffer roles it reads and writes are ``filters.buffers``'.
"""
