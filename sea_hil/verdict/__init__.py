"""The verdict of a session: did it test what it meant to (docs/verdict.md)? `rules` (the rules: a summary in, the
verdict out), `summary_fields` (reading summary.json's fields), `edge_blocks` (the summary blocks of an edge's
`/stats` record). Below both of its judges, summary.json (`sea_hil.report`) and the live view (`sea_hil.live`), so
each applies the same rules: it imports neither.
"""
