//! `backend`: the worker binary. Not functional yet (issue 3): it says so and exits non-zero.
use std::process::ExitCode;

fn main() -> ExitCode {
    eprintln!("backend: the worker service is not implemented yet (see issue 3)");
    ExitCode::FAILURE
}
