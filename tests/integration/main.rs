//! The integration tests: one binary (as ripgrep's tests are), one module per subject.
//!
//! Every module used to be its own test binary, each linking the library and its
//! dependencies once more; one binary links them once. Helpers shared by more than one
//! module live in `common/` (with the ground-segmentation scenes and evaluation as its
//! modules); data stays in `tests/data/` and the reviewed goldens in `tests/golden/`.
//!
//! Run one subject with a filter: `cargo test --test integration -- fuzz::`. Refresh the
//! goldens after a deliberate change with `LIDAR_NOISE_BLESS=1 cargo test`
//! (`common::bless`), then review `git diff tests/golden`.
//!
//! No module changes the process's environment, current directory, global thread pool
//! or allocator, so the modules share this process safely. The one test that must have
//! a process of its own, the sweep's heap peak under a counting global allocator, is
//! the second binary, `tests/sweep_memory/main.rs`.

mod common;

mod cli_consistency;
mod cli_run;
mod clock_wrap;
mod cloud_equivalence;
mod cloud_readers;
mod cloud_run;
mod cloud_truth;
mod cluster_bruteforce;
mod compare_command;
mod config_validation;
mod conventions;
mod dataset_dir;
mod dataset_labels;
mod decode_options;
mod decode_robust;
mod decode_shared;
mod fog_calibration;
mod frame_index;
mod fuzz;
mod golden;
mod ground_config;
mod ground_range_image;
mod ground_ransac;
mod ground_real;
mod ground_targets;
mod hostile_inputs;
mod intensity_rule;
mod interactions;
mod kitti_beams;
mod las_output;
mod manual;
mod model_captures;
mod model_chunks;
mod noise_models;
mod object_rule;
mod output_folders;
mod output_safety;
mod pcap_out;
mod pcap_spurious;
mod pipeline_fixture;
mod ply_roundtrip;
mod progress_totals;
mod provenance;
mod python_package;
mod readers_hostile;
mod reliability;
mod repository_files;
mod run_shards;
mod sensor_lasers;
mod sensor_models;
mod sensor_stack;
mod sensor_stages;
mod special_targets;
mod spurious;
mod stdout_full;
mod sweep_growth;
mod sweep_metrics;
mod sweep_page;
mod sweep_progress;
mod sweep_resume;
mod sweep_shards;
mod sweep_spurious;
mod synth_capture;
mod synth_command;
mod synth_decode;
mod synth_geometry;
mod synth_labels;
mod synth_scenes;
mod synth_sensors;
mod weather_physics;
mod weather_stages;
mod world_attacks;
mod world_geometry;
