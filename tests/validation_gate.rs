//! The validation gate itself: the tests trust `assert_no_validation_messages`, so prove that
//! the log does catch misuse, both a plain invalid call and a synchronization hazard.

mod common;

use ash::vk;
use gpu_allocator::MemoryLocation;
use vkterrain::driver::memory::Buffer;

#[test]
fn gate_catches_an_invalid_call() {
    let gpu = common::gpu(false);
    common::assert_no_validation_messages(&gpu);
    // A buffer of size 0 violates VUID-VkBufferCreateInfo-size-00912.
    let info = vk::BufferCreateInfo::default()
        .size(0)
        .usage(vk::BufferUsageFlags::TRANSFER_DST);
    if let Ok(buffer) = unsafe { gpu.device.create_buffer(&info, None) } {
        unsafe { gpu.device.destroy_buffer(buffer, None) };
    }
    let log = gpu.validation().unwrap();
    assert!(log.count() >= 1, "the invalid call went unnoticed");
    assert!(
        log.messages()
            .iter()
            .any(|m| m.contains("VUID-VkBufferCreateInfo-size")),
        "unexpected messages: {:#?}",
        log.messages()
    );
}

#[test]
fn gate_catches_a_missing_barrier() {
    let gpu = common::gpu(false);
    let buffer = Buffer::new(
        &gpu,
        "hazard",
        1024,
        vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuOnly,
    )
    .unwrap();
    // Two transfer writes to the same bytes with no barrier between: WRITE_AFTER_WRITE.
    gpu.one_shot(|cmd| unsafe {
        gpu.device.cmd_fill_buffer(cmd, buffer.raw, 0, 1024, 1);
        gpu.device.cmd_fill_buffer(cmd, buffer.raw, 0, 1024, 2);
    })
    .unwrap();
    drop(buffer);
    let log = gpu.validation().unwrap();
    assert!(
        log.messages()
            .iter()
            .any(|m| m.contains("SYNC-HAZARD-WRITE-AFTER-WRITE")),
        "synchronization validation did not report the hazard: {:#?}",
        log.messages()
    );
}
