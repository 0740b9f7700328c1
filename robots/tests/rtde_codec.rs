//! RTDE codec: round trips of every package and data type, the variable table, and property
//! tests that decoding arbitrary bytes never panics and never allocates beyond the payload.

use proptest::prelude::*;
use robots::rtde::package::{
    CodecError, MAX_NAMES_LEN, Protocol, Reply, Request, TextMessage, split_frame,
};
use robots::rtde::types::{DataType, Slot, Value};
use robots::rtde::variables::{Register, canonical_type, input_type, output_type};
use robots::rtde::{ControllerVersion, Recipe};

fn roundtrip_request(r: &Request, p: Protocol) -> Request {
    let mut buf = Vec::new();
    r.encode(p, &mut buf).unwrap();
    let (ty, payload, len) = split_frame(&buf).unwrap().unwrap();
    assert_eq!(len, buf.len());
    Request::decode(ty, payload, p).unwrap()
}

fn roundtrip_reply(r: &Reply, p: Protocol) -> Reply {
    let mut buf = Vec::new();
    r.encode(p, &mut buf).unwrap();
    let (ty, payload, len) = split_frame(&buf).unwrap().unwrap();
    assert_eq!(len, buf.len());
    Reply::decode(ty, payload, p).unwrap()
}

#[test]
fn protocol_version_request_matches_the_wire_bytes() {
    let mut buf = Vec::new();
    Request::ProtocolVersion(2)
        .encode(Protocol::V2, &mut buf)
        .unwrap();
    assert_eq!(buf, [0, 5, b'V', 0, 2]);
}

#[test]
fn every_request_round_trips_in_both_versions() {
    let text = TextMessage {
        message: "hello".into(),
        source: "test".into(),
        level: 2,
    };
    for p in [Protocol::V1, Protocol::V2] {
        let requests = [
            Request::ProtocolVersion(2),
            Request::ControllerVersion,
            Request::SetupOutputs {
                frequency: (p == Protocol::V2).then_some(500.0),
                names: vec!["actual_q".into(), "timestamp".into()],
            },
            Request::SetupInputs {
                names: vec!["input_int_register_24".into()],
            },
            Request::Start,
            Request::Pause,
            Request::Data {
                recipe_id: 3,
                payload: vec![1, 2, 3, 4],
            },
        ];
        for r in &requests {
            assert_eq!(&roundtrip_request(r, p), r, "{p:?}");
        }
        let back = roundtrip_request(&Request::Text(text.clone()), p);
        let Request::Text(t) = back else {
            panic!("not a text")
        };
        assert_eq!(t.message, "hello");
        assert_eq!(t.level, 2);
        if p == Protocol::V2 {
            assert_eq!(t.source, "test");
        }
    }
}

#[test]
fn every_reply_round_trips_in_both_versions() {
    for p in [Protocol::V1, Protocol::V2] {
        let id = (p == Protocol::V2).then_some(1);
        let replies = [
            Reply::ProtocolVersion { accepted: true },
            Reply::ControllerVersion(ControllerVersion {
                major: 5,
                minor: 15,
                bugfix: 0,
                build: 12345,
            }),
            Reply::SetupOutputs {
                recipe_id: id,
                slots: vec![
                    Slot::Type(DataType::Vector6d),
                    Slot::NotFound,
                    Slot::Type(DataType::Bool),
                ],
            },
            Reply::SetupInputs {
                recipe_id: 2,
                slots: vec![Slot::Type(DataType::Int32), Slot::InUse],
            },
            Reply::Start { accepted: false },
            Reply::Pause { accepted: true },
            Reply::Data {
                recipe_id: id,
                payload: vec![9, 8, 7],
            },
        ];
        for r in &replies {
            assert_eq!(&roundtrip_reply(r, p), r, "{p:?}");
        }
    }
}

#[test]
fn trailing_comma_of_ur_rtde_is_ignored() {
    let mut payload = 125.0f64.to_be_bytes().to_vec();
    payload.extend_from_slice(b"timestamp,actual_q,");
    let r = Request::decode(b'O', &payload, Protocol::V2).unwrap();
    assert_eq!(
        r,
        Request::SetupOutputs {
            frequency: Some(125.0),
            names: vec!["timestamp".into(), "actual_q".into()]
        }
    );
}

#[test]
fn name_lists_over_2048_bytes_are_refused() {
    let long = "a".repeat(MAX_NAMES_LEN + 1);
    assert_eq!(
        Request::decode(b'I', long.as_bytes(), Protocol::V2),
        Err(CodecError::NamesTooLong(MAX_NAMES_LEN + 1))
    );
    let ok = "a".repeat(MAX_NAMES_LEN);
    assert!(Request::decode(b'I', ok.as_bytes(), Protocol::V2).is_ok());
    let too_many = vec!["x".repeat(MAX_NAMES_LEN), "y".into()];
    assert!(matches!(
        Request::SetupInputs { names: too_many }.encode(Protocol::V2, &mut Vec::new()),
        Err(CodecError::NamesTooLong(_))
    ));
}

#[test]
fn malformed_packages_give_typed_errors() {
    assert_eq!(split_frame(&[0, 2, b'V']), Err(CodecError::SizeTooSmall(2)));
    assert_eq!(split_frame(&[0, 5, b'V', 0]), Ok(None));
    assert_eq!(
        Request::decode(b'V', &[0], Protocol::V2),
        Err(CodecError::Truncated {
            ty: 'V',
            need: 2,
            got: 1
        })
    );
    assert_eq!(
        Request::decode(b'S', &[0], Protocol::V2),
        Err(CodecError::TrailingBytes { ty: 'S', extra: 1 })
    );
    assert_eq!(
        Request::decode(b'X', &[], Protocol::V2),
        Err(CodecError::UnknownType(b'X'))
    );
    assert_eq!(
        Reply::decode(b'O', b"\x01DOUBLE,FLOAT", Protocol::V2),
        Err(CodecError::UnknownDataType("FLOAT".into()))
    );
    assert_eq!(
        Request::decode(b'I', &[0xff, b'a'], Protocol::V2),
        Err(CodecError::NotAscii('I'))
    );
    assert_eq!(
        Request::decode(b'I', b",", Protocol::V2),
        Err(CodecError::EmptyRecipe)
    );
}

#[test]
fn canonical_types_follow_the_table() {
    for (name, ty) in [
        ("timestamp", DataType::Double),
        ("actual_q", DataType::Vector6d),
        ("actual_TCP_pose", DataType::Vector6d),
        ("robot_mode", DataType::Int32),
        ("joint_mode", DataType::Vector6Int32),
        ("runtime_state", DataType::Uint32),
        ("actual_digital_output_bits", DataType::Uint64),
        ("actual_tool_accelerometer", DataType::Vector3d),
        ("standard_digital_output_mask", DataType::Uint8),
        ("output_int_register_47", DataType::Int32),
        ("input_double_register_0", DataType::Double),
        ("output_bit_register_64", DataType::Bool),
        ("input_bit_register_127", DataType::Bool),
    ] {
        assert_eq!(canonical_type(name), Some(ty), "{name}");
    }
    assert_eq!(output_type("output_int_register_48"), None);
    assert_eq!(output_type("output_int_register_07"), None);
    assert_eq!(output_type("output_bit_register_63"), None);
    assert_eq!(output_type("no_such_variable"), None);
    assert_eq!(input_type("actual_q"), None, "outputs are not writable");
    assert_eq!(input_type("output_int_register_24"), None);
    assert_eq!(
        Register::parse("input_int_register_24"),
        Some(Register::InputInt(24))
    );
}

fn value_strategy() -> impl Strategy<Value = Value> {
    let f = any::<f64>().prop_filter("NaN never compares equal", |x| !x.is_nan());
    prop_oneof![
        any::<bool>().prop_map(Value::Bool),
        any::<u8>().prop_map(Value::Uint8),
        any::<u32>().prop_map(Value::Uint32),
        any::<i32>().prop_map(Value::Int32),
        any::<u64>().prop_map(Value::Uint64),
        f.clone().prop_map(Value::Double),
        prop::array::uniform3(f.clone()).prop_map(Value::Vector3d),
        prop::array::uniform6(f).prop_map(Value::Vector6d),
        prop::array::uniform6(any::<i32>()).prop_map(Value::Vector6Int32),
        prop::array::uniform6(any::<u32>()).prop_map(Value::Vector6Uint32),
    ]
}

proptest! {
    #[test]
    fn values_round_trip_through_a_recipe(values in prop::collection::vec(value_strategy(), 1..40)) {
        let types: Vec<DataType> = values.iter().map(Value::data_type).collect();
        let names = (0..values.len()).map(|i| format!("v{i}")).collect();
        let recipe = Recipe::new(1, names, types);
        let mut bytes = Vec::new();
        recipe.encode(&values, &mut bytes).unwrap();
        prop_assert_eq!(bytes.len(), recipe.payload_len());
        prop_assert_eq!(recipe.decode(&bytes).unwrap(), values);
    }

    #[test]
    fn decoding_arbitrary_bytes_never_panics(ty in any::<u8>(), payload in prop::collection::vec(any::<u8>(), 0..3000)) {
        for p in [Protocol::V1, Protocol::V2] {
            let _ = Request::decode(ty, &payload, p);
            let _ = Reply::decode(ty, &payload, p);
        }
        let _ = split_frame(&payload);
        let recipe = Recipe::new(1, vec!["a".into(), "b".into()], vec![DataType::Vector6d, DataType::Bool]);
        let _ = recipe.decode(&payload);
    }

    #[test]
    fn decoding_rtde_like_bytes_never_panics(
        ty in prop::sample::select(b"VvOISPUMx".to_vec()),
        payload in prop::collection::vec(prop::sample::select(b"\x00\x01\xff,ABDEFGLNOTU_0123456789abcdeq".to_vec()), 0..300),
    ) {
        for p in [Protocol::V1, Protocol::V2] {
            let _ = Request::decode(ty, &payload, p);
            let _ = Reply::decode(ty, &payload, p);
        }
    }

    #[test]
    fn names_round_trip(names in prop::collection::vec("[a-z_]{1,30}", 1..40)) {
        let r = Request::SetupInputs { names: names.clone() };
        let mut buf = Vec::new();
        r.encode(Protocol::V2, &mut buf).unwrap();
        let (ty, payload, _) = split_frame(&buf).unwrap().unwrap();
        prop_assert_eq!(Request::decode(ty, payload, Protocol::V2).unwrap(), r);
    }
}
