//! Property tests: whatever arrives from the network, decoding it never panics. Every message
//! type of the protocol from random bytes and from valid messages with bytes changed; object
//! chunks with arbitrary fields through the assembler a worker stores them with; boards with
//! arbitrary bytes through the decoder the visualization node reads them with. (The mesh
//! loaders have their own property tests in `scene/tests/fuzz.rs`.)

use proptest::prelude::*;
use prost::Message;
use proto::{
    BoardChunk, ObjectAssembler, ObjectChunk, RenderRequest, StatusRequest, StoreReply,
    WorkerStatus,
};

/// Decodes `bytes` as every message type; `Ok` or `Err` are both fine.
fn decode_all(bytes: &[u8]) {
    let _ = ObjectChunk::decode(bytes);
    let _ = StoreReply::decode(bytes);
    let _ = RenderRequest::decode(bytes);
    let _ = BoardChunk::decode(bytes);
    let _ = StatusRequest::decode(bytes);
    let _ = WorkerStatus::decode(bytes);
}

/// One valid encoding of each message type, to mutate.
fn valid_messages() -> Vec<Vec<u8>> {
    let object = &integration_tests::small_objects(1, 64)[0];
    let mut messages: Vec<Vec<u8>> = proto::object_to_chunks(7, object)
        .iter()
        .map(Message::encode_to_vec)
        .collect();
    messages.push(
        RenderRequest {
            object_id: 7,
            dir_x: 0.3,
            dir_y: -0.2,
            dir_z: -1.0,
            size: 64,
            priority: 12.5,
        }
        .encode_to_vec(),
    );
    messages.push(
        BoardChunk {
            data: valid_board(),
            total_bytes: 100,
            render_milliseconds: 1.5,
        }
        .encode_to_vec(),
    );
    messages.push(
        WorkerStatus {
            queue_length: 3,
            queue_capacity: 64,
            outstanding_triangles: 1000,
            triangles_per_second: 1e6,
            objects: 4,
            memory_bytes: 1 << 20,
            boards_rendered: 9,
            instance: 0x5eed,
            boards_cancelled: 2,
            objects_simplifying: 1,
            boards_rendering: 1,
        }
        .encode_to_vec(),
    );
    messages.push(
        StoreReply {
            object_id: 7,
            triangles: 64,
        }
        .encode_to_vec(),
    );
    messages
}

/// The encoding of a real board, small.
fn valid_board() -> Vec<u8> {
    let object = &integration_tests::small_objects(1, 64)[0];
    let prepared = backend::PreparedObject::new(object).unwrap();
    let maps = backend::render_maps(&prepared, glam::DVec3::new(0.2, -0.3, -1.0), 24, 1).unwrap();
    backend::EncodedBoard::encode(&maps).bytes
}

fn mutate(mut bytes: Vec<u8>, edits: &[(usize, u8)], cut: Option<usize>) -> Vec<u8> {
    for &(at, value) in edits {
        if !bytes.is_empty() {
            let at = at % bytes.len();
            bytes[at] = value;
        }
    }
    if let Some(cut) = cut {
        bytes.truncate(cut % (bytes.len() + 1));
    }
    bytes
}

fn chunk_strategy() -> impl Strategy<Value = ObjectChunk> {
    (
        any::<u32>(),
        prop_oneof![Just(0u64), 0u64..64, any::<u64>()],
        prop_oneof![Just(0u64), 0u64..64, any::<u64>()],
        proptest::collection::vec(any::<u8>(), 0..256),
        proptest::collection::vec(any::<u8>(), 0..128),
        proptest::collection::vec(any::<u8>(), 0..256),
        any::<f64>(),
        proptest::collection::vec(0u8..3, 0..32),
    )
        .prop_map(
            |(
                object_id,
                total_vertices,
                total_triangles,
                positions,
                colors,
                triangles,
                x,
                seams,
            )| {
                ObjectChunk {
                    object_id,
                    name: "fuzz".into(),
                    origin_x: x,
                    origin_y: 0.0,
                    origin_z: -x,
                    total_vertices,
                    total_triangles,
                    positions,
                    colors,
                    triangles,
                    seams,
                }
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_decode_as_no_message_with_a_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..1024),
    ) {
        decode_all(&bytes);
    }

    #[test]
    fn mutated_valid_messages_never_panic(
        which in any::<prop::sample::Index>(),
        edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..8),
        cut in proptest::option::of(any::<usize>()),
    ) {
        let messages = valid_messages();
        let bytes = mutate(which.get(&messages).clone(), &edits, cut);
        decode_all(&bytes);
        if let Ok(chunk) = BoardChunk::decode(&bytes[..]) {
            let _ = backend::EncodedBoard { bytes: chunk.data }.decode();
        }
    }

    /// A worker assembles whatever chunks it is sent: an error, never a panic, and never
    /// more than its limit of elements.
    #[test]
    fn arbitrary_object_chunks_assemble_or_fail_cleanly(
        chunks in proptest::collection::vec(chunk_strategy(), 1..6),
    ) {
        let mut assembler = ObjectAssembler::new(1 << 16);
        let mut failed = false;
        for chunk in chunks {
            if assembler.push(chunk).is_err() {
                failed = true;
                break;
            }
        }
        if !failed
            && let Ok((_, object)) = assembler.finish()
        {
            prop_assert!(object.triangle_count() <= 1 << 16);
            // A stored object must be renderable or refused, not crash the worker.
            let _ = backend::PreparedObject::new(&object);
        }
    }

    /// The node decodes whatever board bytes a worker sends.
    #[test]
    fn arbitrary_board_bytes_decode_or_fail_cleanly(
        edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..16),
        cut in proptest::option::of(any::<usize>()),
        random in proptest::collection::vec(any::<u8>(), 0..512),
    ) {
        let _ = backend::EncodedBoard { bytes: random }.decode();
        let bytes = mutate(valid_board(), &edits, cut);
        if let Ok(maps) = (backend::EncodedBoard { bytes }).decode() {
            let _ = visnode::board::BoardData::new(
                &maps,
                glam::DVec3::new(0.2, -0.3, -1.0).normalize(),
                visnode::board::BoardShape::Relief {
            grid_cells: 8,
            cell_pixels: 1,
        },
            );
        }
    }
}
