//! Any bytes as an encoded board from a worker: an error, or maps the node can turn into a
//! board (finite basis, consistent sizes), never a panic or an allocation past the board's
//! declared size.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    if let Ok(maps) = (backend::EncodedBoard {
        bytes: bytes.to_vec(),
    })
    .decode()
    {
        assert!(maps.basis.check().is_ok());
        let board = backend::Board::from_maps(maps);
        assert!(board.vertices.iter().all(|v| v.position.is_finite()));
    }
});
