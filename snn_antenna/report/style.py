"""The style sheet every report.html carries (snn_antenna/report/page.py)."""

# The page never grows wider than its column and no box hides a cell: tables are cut to fit
# (_table_html), their text wraps, images shrink to fit, long words break.
CSS = """
body{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto;padding:0 1em;
color:#222;line-height:1.4;overflow-wrap:anywhere}
h1{font-size:1.6em}
.run-identity{display:grid;grid-template-columns:max-content minmax(0,1fr);gap:.1em .8em;
margin:0 0 1em;font-size:.85em;color:#444} .run-identity dt{font-weight:600}
.run-identity dd{margin:0} h2{margin-top:1.6em;border-bottom:1px solid #ddd}
.quick-banner{background:#fff3cd;border:2px solid #e0a800;border-left-width:.6em;
border-radius:4px;padding:.7em 1em;margin:1em 0}
.quick-banner strong{display:block;font-size:1.15em;color:#7a5200;text-transform:uppercase;
letter-spacing:.04em} .quick-banner span{display:block;font-weight:600;margin:.2em 0}
.quick-banner small{display:block;color:#5c4a00}
.lead{font-size:1.08em;border-left:4px solid #4a7bb7;padding:.3em .8em;background:#f4f8fc}
.table-scroll{max-width:100%;overflow-x:auto;margin:1em 0}
table{border-collapse:collapse;font-size:.9em;max-width:100%;overflow-wrap:break-word}
caption{caption-side:top;text-align:left;color:#555;padding:.3em 0}
td,th{border:1px solid #ccc;padding:.25em .6em;text-align:right;vertical-align:top}
th{background:#f3f3f3;font-weight:600}
th .key{display:block;font-weight:normal;font-size:.72em;color:#888;font-family:monospace}
th.text,td.text{text-align:left}
table.nested{font-size:1em;margin:0;width:100%} table.nested td,table.nested th{border:0;
border-bottom:1px solid #eee;padding:.05em .4em} table.nested th{background:none;
text-align:left;color:#555;font-weight:normal}
img{max-width:100%;height:auto} figure{margin:1.2em 0}
figcaption{color:#555;font-size:.9em}
pre{background:#f7f7f7;padding:1em;white-space:pre-wrap;overflow-wrap:anywhere}
@media print{body{max-width:none;margin:0} .table-scroll{overflow:visible}
table{font-size:.8em} img{max-width:100%} figure,table{break-inside:avoid}}
"""
