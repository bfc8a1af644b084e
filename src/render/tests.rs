use super::merge_sorted;

#[test]
fn merging_sorted_lists_gives_their_union_sorted_once() {
    assert_eq!(
        merge_sorted(&[1, 4, 9], &[2, 4, 10, 11]),
        vec![1, 2, 4, 9, 10, 11]
    );
    assert_eq!(merge_sorted(&[], &[3, 3, 5]), vec![3, 5]);
    assert_eq!(merge_sorted(&[7], &[]), vec![7]);
    assert!(merge_sorted(&[], &[]).is_empty());
}
