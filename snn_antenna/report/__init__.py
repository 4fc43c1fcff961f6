"""A study's report: the HTML page (``page``), its style, shared figures and the statistics
behind every claim across seeds (``stats``). Imports only the core."""
