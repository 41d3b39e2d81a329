//! The backend worker: keeps replicas of objects and software-renders reliefboards on request.
//! The renderer and the gRPC service arrive with issue 3.
//!
//! **Architecture invariant:** depends on `scene` and `proto`, never on `visnode` or
//! `balancer`; needs no GPU.
