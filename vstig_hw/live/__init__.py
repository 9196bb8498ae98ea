"""The live view (`sniff/bridge --foxglove`): the gateway's side (`view`), the server process (`server`,
Foxglove's SDK) and each write's spread measured live (`spread`). Needs the `live` extra."""
