//! Rays, boxes and the watertight triangle test.
