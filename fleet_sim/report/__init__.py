"""The report of a sweep or sizing search: `report` reads the results folder into plain data,
`render` turns it into HTML (Jinja2 templates in ``templates/``, autoescape on) and a PDF;
`figures` and `layout_plot` draw with matplotlib (Agg)."""
