"""Maps and reports: matplotlib figures and the self-contained HTML report.

matplotlib and plotly are imported only here.
"""
