"""`vstig demo`: a swarm on this PC alone (virtual CAN, pty radios), with the gateway between its media."""
