//! Parallel subfields: directions, tile grids, conservative raster, 1D BSP, traversal.
