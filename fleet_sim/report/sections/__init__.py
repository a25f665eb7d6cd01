"""The sections of a sweep's or sizing's report, one module each beside its template
(templates/sections/<name>.html.j2): each builds its section's data, text and figures from a
`ReportData`. fleet_sim.report.study_report puts them together.
"""
