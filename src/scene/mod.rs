//! Scene model, glTF import/export, animation sampling, static/dynamic split.
