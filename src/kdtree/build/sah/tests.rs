//! Tests of the SAH split search (src/kdtree/build/sah.rs).

use super::*;

#[test]
fn radix_sort_sorts_events_made_in_triangle_order() {
    let mut rng = crate::raygen::SplitMix64(0x9E37_79B9_7F4A_7C15);
    for len in [0, 1, 100, 5000, 70_000] {
        let mut events = Vec::new();
        for i in 0..len as u32 {
            let seed = rng.next_u64();
            // Few distinct positions (many equal ones), some negative, some flat boxes.
            let lo = ((seed >> 33) % 64) as f32 - 20.0;
            let hi = if seed % 5 == 0 { lo } else { lo + ((seed >> 20) % 9) as f32 * 0.25 };
            push_events(&mut events, &Aabb::new(Vec3::splat(lo), Vec3::splat(hi)), 0, i);
        }
        let mut expected = events.clone();
        expected.sort_unstable();
        radix_sort_events(&mut events);
        assert_eq!(events, expected, "{len} triangles");
    }
}

#[test]
fn events_sort_like_positions_then_types() {
    let mut values = vec![-3.0f32, -1e-30, 0.0, 1e-30, 2.5, 1e30, -1e30, f32::MIN_POSITIVE];
    let mut keys: Vec<u64> = values.iter().map(|&v| event(ordered(v), PLANAR, 7)).collect();
    keys.sort_unstable();
    values.sort_by(f32::total_cmp);
    assert_eq!(keys.iter().map(|&k| from_ordered(event_key(k))).collect::<Vec<_>>(), values);
    assert!(event(ordered(1.0), END, 9) < event(ordered(1.0), PLANAR, 0));
    assert!(event(ordered(1.0), PLANAR, 9) < event(ordered(1.0), START, 0));
    assert_eq!(ordered(-0.0), ordered(0.0));
    let e = event(ordered(-2.5), START, 12345);
    assert_eq!((from_ordered(event_key(e)), event_kind(e), event_index(e)), (-2.5, START, 12345));
}
