// Pieces shared by the recog subcommands that talk to recogd (besides ServerFlags): wiring a
// subcommand to a connected client, frames made from the image files they read, intrinsics from
// --camera, labels and times as they print them, and one-line errors.
//
// Image files go as their own JPEG or PNG bytes: the server decodes them as the offline commands
// read them (8-bit grey), so a map or a recognition on the server answers exactly as `recog eval
// place` or offline `recog recognize` does on the same files. Other formats (BMP, PGM, TIFF...)
// and video frames go as raw grey pixels, decoded here.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include <grpcpp/support/status.h>
#include <CLI/CLI.hpp>
#include <opencv2/core.hpp>

#include "client/cpp/frames.h"
#include "client/cpp/recognition_client.h"
#include "client/cpp/result.h"
#include "core/common/status.h"
#include "core/object/model/object_model.h"
#include "tools/common/cli_support.h"

namespace recog::cli {

namespace pb = ::recognition::v1;

struct ServerFlags;

// Adds the ServerFlags to `command`, bound to *flags (which must outlive it). When the command
// runs, it connects as the flags say and stores run(client)'s exit status in *exit_code, or 1
// after the line "recog <command>: CODE: message" when it cannot connect.
void ConnectCommand(CLI::App* command, ServerFlags* flags, int* exit_code,
                    std::function<int(client::RecognitionClient&)> run);

// The frame of the image file `path`, whose grey pixels (ReadGrayImage, FrameSource) are `gray`:
// the file's bytes when it is a JPEG or PNG, else `gray` raw. NOT_FOUND when it cannot be read.
client::Result<pb::Frame> FrameFromImageFile(const std::string& path, const cv::Mat& gray);

// Sets the frame's intrinsics (pinhole and distortion) to `camera`.
void SetIntrinsics(const CameraIntrinsics& camera, pb::Frame* frame);

// The error of a client frame-preparation helper (client/cpp/frames.h), which reports NOT_FOUND
// or INVALID_ARGUMENT, as core's Status.
Status FromClient(const grpc::Status& status);

// A bag frame's 3D structure for recogd: with `camera`, the frame's intrinsics (without
// distortion when a depth or right image goes with them), and `depth` (16UC1 millimetres or
// 32FC1 metres, AttachDepth) or else `right` (a rectified pair `baseline` metres wide,
// AttachStereoRight); empty images are none. INVALID_ARGUMENT for a depth or right image without
// a camera, a right image without a baseline, or what the client refuses.
Status AttachBagGeometry(const std::optional<CameraIntrinsics>& camera,
                         std::optional<double> baseline, const cv::Mat& depth, const cv::Mat& right,
                         pb::Frame* frame);

// A proto enum value's name without its prefix, in lower case: "loop_detected" for
// LOOP_STATUS_LOOP_DETECTED (core's spelling, as `recog eval place` prints it).
std::string EnumLabel(std::string name, std::string_view prefix);

// "2024-05-01T12:00:00Z".
std::string UtcTime(int64_t unix_ms);

// Fail (cli_support.h) for a call to recogd: "recog <command>: CODE: message" on stderr, returns 1.
int Fail(const char* command, const grpc::Status& status);

}  // namespace recog::cli
