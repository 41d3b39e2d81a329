//! Any bytes as a store stream: length-prefixed (u16, little-endian) protobuf
//! `ObjectChunk`s fed to the worker's assembler, then prepared as the worker would. An error
//! or an object, never a panic, and never an allocation the declared limit does not allow.
#![no_main]

use libfuzzer_sys::fuzz_target;
use prost::Message;

fuzz_target!(|bytes: &[u8]| {
    let mut assembler = proto::ObjectAssembler::new(1_000_000);
    let mut rest = bytes;
    while let Some((length, tail)) = rest.split_first_chunk::<2>() {
        let length = (u16::from_le_bytes(*length) as usize).min(tail.len());
        let (message, tail) = tail.split_at(length);
        rest = tail;
        let Ok(chunk) = proto::ObjectChunk::decode(message) else {
            return;
        };
        if assembler.push(chunk).is_err() {
            return;
        }
    }
    if let Ok((_, object)) = assembler.finish() {
        let _ = backend::PreparedObject::new(&object);
    }
});
