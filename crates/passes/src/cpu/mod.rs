//! CPU mirrors of the GPU passes, one module per pass with the same name
//! (`cpu::transfer` ↔ `transfer.rs` + `shaders/transfer.wgsl`, …), written to be read line
//! by line beside the shader. They are the references of the GPU-vs-CPU tests and a
//! reference mode for the viewer; they favour clarity over speed.

pub mod dilate;
pub mod display;
pub mod first_order;
pub mod indirect;
pub mod pyramid;
pub mod transfer;
pub mod transfer_gather;
pub mod transfer_rows;
