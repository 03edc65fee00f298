//! The one process-wide setting: Burn's default device, pinned to the CPU so that loading
//! Adam's state (which Burn materialises on `Device::default()`) never needs a GPU. Its own
//! test binary, since it sets an environment variable.

use burn::tensor::Device;

#[test]
fn the_default_device_is_pinned_to_flex_unless_the_user_named_one() {
    // SAFETY: the only test in this process, before any other thread of ours exists.
    unsafe {
        std::env::remove_var("BURN_DEVICE");
        doma::backend::pin_default_device();
    }
    assert_eq!(std::env::var("BURN_DEVICE").as_deref(), Ok("flex"));
    let default = format!("{:?}", Device::default()).to_lowercase();
    assert!(default.contains("flex"), "{default}");
    // A user's own choice is kept.
    // SAFETY: as above.
    unsafe {
        std::env::set_var("BURN_DEVICE", "ndarray");
        doma::backend::pin_default_device();
    }
    assert_eq!(std::env::var("BURN_DEVICE").as_deref(), Ok("ndarray"));
}
