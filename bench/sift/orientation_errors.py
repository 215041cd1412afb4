"""Orientation error and descriptor distance of corresponding keypoints, by scale.

For the rot15, rot45 and bright-40 warps of three base images: keypoints of image A whose
mapped position has a keypoint of B within 1 px and 15 % in scale; among those, the smallest
orientation error against the warp's rotation, the L2 distance of the two descriptors
(relative to A's norm) and the position error. OpenCV's SIFT against ours, capped at
OpenCV's count. Usage: python3 bench/sift/orientation_errors.py "FEATURES FLAGS"
"""
import sys, os, tempfile, numpy as np, cv2
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench
extra = sys.argv[1].split() if len(sys.argv) > 1 else []
data = bench.default_data()
bases = [b for b in bench.base_images(data) if b[0] in ('leuvenA','box_in_scene','aero1')]
ws = [w for w in bench.warps() if w[0] in ('rot15','rot45','bright-40')]
binp = os.path.join(bench.ROOT, 'target', 'release', 'phototraverse')
def cv_full(img):
    s = cv2.SIFT_create(); k, d = s.detectAndCompute(img, None)
    return np.array([p.pt for p in k]), np.array([p.size/2 for p in k]), np.array([p.angle for p in k]), d.astype(np.float32)
edges=[0,1.2,1.6,2.3,3.2,100]
res = {}
with tempfile.TemporaryDirectory() as tmp:
  for bname, img in bases:
    for i,(wname, hm, photo) in enumerate(bench.warps()):
        if wname not in ('rot15','rot45','bright-40'): continue
        b = bench.apply_warp(img, hm, photo, i); H = bench.Homography(hm)
        ang = {'rot15':15,'rot45':45,'bright-40':0}[wname]
        for who in ('cv','ours'):
            out=[]
            for im in (img,b):
                if who=='cv':
                    out.append(cv_full(im))
                else:
                    n = len(cv2.SIFT_create().detect(im,None))
                    src=os.path.join(tmp,'i.png'); f=os.path.join(tmp,'f.txt'); cv2.imwrite(src,im)
                    import subprocess; subprocess.run([binp,'features',src,'--out',f,'--max-keypoints',str(n)]+extra,check=True,capture_output=True)
                    r=np.loadtxt(f,skiprows=1,ndmin=2)
                    # ours orientation: radians, y down; cv angle: degrees, 360-... 
                    out.append((r[:,:2]-0.5, r[:,2], np.rad2deg(r[:,3]), r[:,4:].astype(np.float32)))
            (pa,sa,aa,da),(pb,sb,ab,db)=out
            q=H.map(pa)
            # nearest keypoint in b
            from scipy.spatial import cKDTree
            t=cKDTree(pb); dist,j=t.query(q,k=4)
            for ii in range(len(pa)):
                best=None
                for kk in range(4):
                    jj=j[ii,kk]
                    if dist[ii,kk]<1.0 and abs(np.log(sb[jj]/sa[ii]))<0.15:
                        d=(ab[jj]-aa[ii]) % 360
                        exp = ang%360
                        e=abs(((d-exp+180)%360)-180)
                        dd=np.linalg.norm(da[ii]-db[jj])/max(np.linalg.norm(da[ii]),1)
                        if best is None or e<best[0]: best=(e,dd,dist[ii,kk])
                if best:
                    bi=np.digitize(sa[ii],edges)-1
                    res.setdefault((who,wname,bi),[]).append(best)
for who in ('cv','ours'):
  for w in ('rot15','rot45','bright-40'):
    for bi in range(len(edges)-1):
        v=np.array(res.get((who,w,bi),[(np.nan,np.nan)]))
        print(f"{who:4} {w:9} sigma {edges[bi]:4}-{edges[bi+1]:4}: n {len(v):5d} ori err median {np.median(v[:,0]):5.2f} p80 {np.percentile(v[:,0],80):5.2f} >10deg {np.mean(v[:,0]>10):.3f} desc dist median {np.median(v[:,1]):.3f} pos {np.median(v[:,2]):.3f}")
