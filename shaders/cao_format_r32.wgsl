// CAO's volumes in R32Float (4 bytes per voxel): what ao::cao::pipelines includes instead
// of cao_format.wgsl where the adapter cannot write R16Float from a shader.
alias CaoWrite = texture_storage_3d<r32float, write>;
alias CaoReadWrite = texture_storage_3d<r32float, read_write>;
