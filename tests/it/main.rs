//! Integration scenarios, one module each, through public APIs only.

mod ddp_finger;
mod ddp_solver;
mod dynamics_hard_cases;
mod dynamics_joints;
mod dynamics_laws;
mod dynamics_reference;
mod dynamics_world;
mod geometry_laws;
mod geometry_reference;
mod library_anneal;
mod library_files;
mod library_policy;
mod library_tasks;
mod ncp_functions;
mod ncp_solvers;
mod support;
mod trust_inputs;
mod trust_physics;
mod viewer_browser;
mod viewer_protocol;
mod viewer_world;
