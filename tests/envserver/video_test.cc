// Tests of MP4 writing (read back with OpenCV) and of the side-by-side frame layout.
#include "indrive/envserver/video.h"

#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgproc.hpp>

#include "testing.h"

namespace indrive::env {
namespace {

TEST(VideoWriterTest, WritesAnMp4ThatReadsBackWithFramesAndColours) {
  indrive::testing::TempDir dir;
  const auto path = dir.path() / "sub" / "clip.mp4";
  {
    VideoWriter video(path, cv::Size(64, 48), 10.0);
    for (int k = 0; k < 12; ++k) {
      // RGB red for the first half, RGB blue for the second.
      video.write(cv::Mat(48, 64, CV_8UC3, k < 6 ? cv::Scalar(255, 0, 0) : cv::Scalar(0, 0, 255)));
    }
    EXPECT_EQ(video.frames_written(), 12);
  }
  ASSERT_TRUE(std::filesystem::exists(path));
  cv::VideoCapture capture(path.string(), cv::CAP_FFMPEG);
  ASSERT_TRUE(capture.isOpened());
  EXPECT_EQ(static_cast<int>(capture.get(cv::CAP_PROP_FRAME_WIDTH)), 64);
  EXPECT_EQ(static_cast<int>(capture.get(cv::CAP_PROP_FRAME_HEIGHT)), 48);
  int frames = 0;
  cv::Mat bgr;
  while (capture.read(bgr)) {
    const cv::Vec3b centre = bgr.at<cv::Vec3b>(24, 32);
    if (frames < 6) {
      EXPECT_GT(centre[2], 200) << "frame " << frames << " should be red (BGR read back)";
      EXPECT_LT(centre[0], 60);
    } else {
      EXPECT_GT(centre[0], 200) << "frame " << frames << " should be blue";
      EXPECT_LT(centre[2], 60);
    }
    ++frames;
  }
  EXPECT_EQ(frames, 12);
}

TEST(VideoWriterTest, BadInputsThrowVideoError) {
  indrive::testing::TempDir dir;
  // A folder that cannot exist: its parent is a regular file.
  const auto blocker = dir.path() / "file";
  std::ofstream(blocker) << "x";
  EXPECT_THROW(VideoWriter(blocker / "clip.mp4", cv::Size(64, 48)), VideoError);
  EXPECT_THROW(VideoWriter(dir.path() / "odd.mp4", cv::Size(63, 48)), VideoError);
  EXPECT_THROW(VideoWriter(dir.path() / "rate.mp4", cv::Size(64, 48), 0.0), VideoError);
  VideoWriter video(dir.path() / "ok.mp4", cv::Size(64, 48));
  EXPECT_THROW(video.write(cv::Mat(32, 32, CV_8UC3)), VideoError);
  EXPECT_THROW(video.write(cv::Mat(48, 64, CV_8UC1)), VideoError);
  video.close();
  EXPECT_THROW(video.write(cv::Mat(48, 64, CV_8UC3)), VideoError);
}

TEST(ComposeFrameTest, PlacesCameraAndBevSideBySideWithText) {
  cv::Mat camera(128, 128, CV_8UC3, cv::Scalar(10, 20, 30));
  camera.at<cv::Vec3b>(127, 127) = cv::Vec3b(200, 0, 0);
  cv::Mat bev(256, 256, CV_8UC3, cv::Scalar(40, 50, 60));
  const cv::Mat plain = compose_frame(camera, bev, {}, 256);
  ASSERT_EQ(plain.rows, 256);
  ASSERT_EQ(plain.cols, 512);
  EXPECT_EQ(plain.at<cv::Vec3b>(100, 100), cv::Vec3b(10, 20, 30));
  EXPECT_EQ(plain.at<cv::Vec3b>(100, 300), cv::Vec3b(40, 50, 60));
  // Nearest-neighbour upscaling: the last camera pixel becomes a crisp 2x2 block.
  EXPECT_EQ(plain.at<cv::Vec3b>(254, 254), cv::Vec3b(200, 0, 0));
  EXPECT_EQ(plain.at<cv::Vec3b>(255, 255), cv::Vec3b(200, 0, 0));
  EXPECT_EQ(plain.at<cv::Vec3b>(253, 253), cv::Vec3b(10, 20, 30));
  // Text changes pixels in the top-left corner only.
  const std::vector<std::string> lines = {"step 12", "collision"};
  const cv::Mat text = compose_frame(camera, bev, lines, 256);
  cv::Mat changed;
  cv::cvtColor(text != plain, changed, cv::COLOR_RGB2GRAY);  // nonzero where any channel differs
  EXPECT_GT(cv::countNonZero(changed(cv::Rect(0, 0, 128, 60))), 50);
  EXPECT_EQ(cv::countNonZero(changed(cv::Rect(0, 100, 512, 156))), 0);
  // Odd sizes are padded to even for the codec.
  const cv::Mat odd = compose_frame(cv::Mat(3, 5, CV_8UC3), bev, {}, 101);
  EXPECT_EQ(odd.rows % 2, 0);
  EXPECT_EQ(odd.cols % 2, 0);
  EXPECT_THROW(compose_frame(cv::Mat(), bev, {}, 256), VideoError);
}

TEST(DrawBannerTest, FillsTheBottomFifthWithTheBandAndWhiteText) {
  cv::Mat frame(200, 300, CV_8UC3, cv::Scalar(10, 20, 30));
  draw_banner(frame, "collision+lane_invasion", cv::Scalar(200, 30, 30));
  // Above the band nothing changed.
  cv::Mat unchanged;
  cv::inRange(frame(cv::Rect(0, 0, 300, 160)), cv::Scalar(10, 20, 30), cv::Scalar(10, 20, 30),
              unchanged);
  EXPECT_EQ(cv::countNonZero(unchanged), 300 * 160);
  // The band: its colour at the edges, white text in the middle, all inside the frame width.
  EXPECT_EQ(frame.at<cv::Vec3b>(199, 0), cv::Vec3b(200, 30, 30));
  EXPECT_EQ(frame.at<cv::Vec3b>(161, 299), cv::Vec3b(200, 30, 30));
  cv::Mat white;
  cv::inRange(frame(cv::Rect(0, 160, 300, 40)), cv::Scalar(240, 240, 240),
              cv::Scalar(255, 255, 255), white);
  EXPECT_GT(cv::countNonZero(white), 30);
  EXPECT_EQ(cv::countNonZero(white(cv::Rect(0, 0, 3, 40))), 0);
  cv::Mat empty;
  EXPECT_THROW(draw_banner(empty, "x"), VideoError);
}

}  // namespace
}  // namespace indrive::env
