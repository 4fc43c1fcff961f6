"""The browser view of a live stream: the Bokeh page, its process and history, the page's
controls, saved views and the host guard."""
