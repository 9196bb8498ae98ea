"""The unattended gateway's edge: systemd's notify protocol (`notify`) and the Prometheus endpoint (`metrics`).

Nothing here is on the data path: the notifier pings from the loop's tick, and the metrics server reads
`Node.stats()` when scraped, on its own thread.
"""
