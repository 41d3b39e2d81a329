//! The wire protocol between the visualization node and the backend workers (gRPC, tonic and
//! prost). The service definitions arrive with the backend worker (issue 3); this crate exists
//! now so the workspace has its final shape.
//!
//! **Architecture invariant:** depends on the `scene` crate only (for conversions); knows
//! nothing of wgpu, the balancer or how boards are rendered.
