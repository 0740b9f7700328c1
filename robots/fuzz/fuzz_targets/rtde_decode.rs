//! Fuzz target: any byte sequence through the RTDE framing, both decoders in both protocol
//! versions, and a recipe decode. Must never panic; memory is bounded by the u16 frame size.

#![no_main]

use libfuzzer_sys::fuzz_target;
use robots::rtde::Recipe;
use robots::rtde::package::{Protocol, Reply, Request, split_frame};
use robots::rtde::types::DataType;

fuzz_target!(|data: &[u8]| {
    let recipe = Recipe::new(
        1,
        vec!["q".into(), "mode".into(), "bit".into()],
        vec![DataType::Vector6d, DataType::Int32, DataType::Bool],
    );
    let mut rest = data;
    while let Ok(Some((ty, payload, len))) = split_frame(rest) {
        for p in [Protocol::V1, Protocol::V2] {
            let _ = Request::decode(ty, payload, p);
            if let Ok(Reply::Data { payload, .. }) = Reply::decode(ty, payload, p) {
                let _ = recipe.decode(&payload);
            }
        }
        rest = &rest[len..];
    }
});
