"""Sim-to-real gap diagnosis (msgs_doc/specification.md sections 3-4): the model ladder scored
on data
not used to fit it, the noise floor estimated from the data, where the residual lies."""
