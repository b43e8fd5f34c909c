// The storage format of CAO's volumes V_o, V_PAO and V_AO, as the shaders that write them
// name it: R16Float, 2 bytes per voxel. Where the adapter cannot write R16Float from a
// shader, ao::cao::pipelines resolves `//!include cao_format.wgsl` to cao_format_r32.wgsl.
alias CaoWrite = texture_storage_3d<r16float, write>;
alias CaoReadWrite = texture_storage_3d<r16float, read_write>;
