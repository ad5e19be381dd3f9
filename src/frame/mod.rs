//! What every LOD method draws with, below both `lod` and `render`: descriptor set 0 (the
//! terrain's textures or the clipmap's atlas, and per view slot the frame uniforms) and the
//! view a frame is drawn for.

pub mod terrain;
pub mod uniforms;
pub mod view;

pub use terrain::{TerrainGpu, TerrainInfo};
pub use uniforms::{FrameUniforms, Lighting};
pub use view::ViewState;
