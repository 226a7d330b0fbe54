//! The experiments whose numbers and pictures are the documented results: `reproduce` (the paper's),
//! `seeds` (its claim over library seeds), `diagnose`, `examples` (the task zoo) and `figures`, with what
//! they share (`recipe`: the finger's run length, worlds and settings stamp; `draw`: scene drawing and
//! the PNG and SVG writer).

pub mod diagnose;
pub mod draw;
pub mod examples;
pub mod figures;
pub mod recipe;
pub mod reproduce;
pub mod seeds;
pub mod task_pictures;
