"""The wire: key expressions, message schemas, msgpack codec and validation.
Depends on msgpack and numpy only; the single place where bytes become objects."""
