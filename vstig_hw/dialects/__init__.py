"""The virtual-stigmergy dialects real swarms already speak, beside our own 8-byte format.

- `buzz`: the Buzz VM's vstig PUT/QUERY messages (Khepera IV, ROSBuzz drones, ARGoS),
  in the current one-byte-tag dialect and the pre-July-2017 two-byte-tag one.
- `buzz_packets`: how Buzz transports pack those messages into frames (BuzzKH4 over
  blabbermouth, ARGoS range-and-bearing, ROSBuzz payload blocks and their XBee byte order).
- `bittybuzz`: BittyBuzz's fixed 9-byte message (Kilobots) and its 16-bit float.
- `mapping`: a deployment's TOML file that maps dialect keys and values to our Message.
- `lamport`: BittyBuzz's 8-bit Lamport clock against our 16-bit timestamps.

Every codec here is pure: bytes in, fields out, no I/O. See firmware_spec/dialects.md
for the layouts, their sources and where the research notes proved wrong.
"""
